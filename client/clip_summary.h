// Human-readable summaries the CLI prints: clips, frame rates, retime and reduction reports.
// Every line is "label: value" with the labels padded to one column, so scripts can grep them.
#ifndef TEMPOKEY_CLIENT_CLIP_SUMMARY_H_
#define TEMPOKEY_CLIENT_CLIP_SUMMARY_H_

#include <string>
#include <string_view>

#include "tempokey/core/io/gltf.h"
#include "tempokey/core/model/clip.h"
#include "tempokey/core/model/keyed_clip.h"
#include "tempokey/core/reduce/reduce.h"
#include "tempokey/core/retime/retime.h"

namespace tempokey::client {

// The rate a frame time stands for, snapped for display only to a common rate within 1e-4
// relative ("120 fps", "29.97 fps", "23.976 fps"), else 6 significant digits ("81.3008 fps"),
// followed by the frame time exactly as stored: "120 fps (0.0083333 s)".
// Precondition: `frame_time_seconds` finite and > 0.
std::string FormatFrameRate(double frame_time_seconds);

// "ZYX (19 joints), ZXY (12 joints)": the rotation orders of the clip's joints (the order of
// each joint's rotation channels), most common first, ties in order of first appearance; "none"
// without rotation channels.
std::string FormatRotationOrders(const core::Clip& clip);

// The multi-line summary of `info`, `upload` and written outputs, each line ending in '\n':
//   name:            131_01
//   frames:          994
//   rate:            120 fps (0.0083333 s)
//   duration:        8.275 s
//   joints:          31
//   channels:        96 (6 position, 90 rotation)
//   rotation orders: ZYX (19 joints), ZXY (12 joints)
std::string FormatClipSummary(const core::Clip& clip);

// Label-value lines for a retime report (output frames and duration, fit factor, max
// decimation ratio, filtered samples).
std::string FormatRetimeReport(const core::RetimeReport& report);

// Label-value lines for a reduction report: keys kept of samples with their percentage, RMS and
// max error (degrees for rotations, file units for positions) and the worst channel and frame,
// named through `layout` (the clip the curves came from).
// The world error's lines follow when the report has one (FormatWorldErrorReport()).
std::string FormatReductionReport(const core::ReductionReport& report, const core::Clip& layout);

// Label-value lines for the joint world-position error, in file units and % of the figure's
// height:
//   figure height:   139.3 (first frame)
//   joint max error: 0.9850 (0.707% of height) at Toes_R, frame 94
//   joint rms error: 0.2461 (0.177% of height)
//   joint bound:     1 (0.718% of height)          (only when the reduction kept one)
std::string FormatWorldErrorReport(const core::WorldErrorReport& world);

// Label-value lines for what a keyed glTF holds (its rotations are quaternion keys fitted again,
// so its keys and errors are not the reduction's), with `world` the reduction's world error
// report (for the figure's height) when it has one:
//   gltf keys:       1396 rotation (4.53% of 30814 joint frames), 83 translation
//   gltf joint max:  0.1208 (0.478% of height), bound 0.1264, as glTF plays the file
// (the second line only under a joint bound).
std::string FormatGltfStats(const core::GltfStats& stats, const core::WorldErrorReport* world);

// "label:" padded to the summary's value column.
std::string SummaryLine(std::string_view label, std::string_view value);

}  // namespace tempokey::client

#endif  // TEMPOKEY_CLIENT_CLIP_SUMMARY_H_
