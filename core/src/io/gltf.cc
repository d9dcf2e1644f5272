// glTF 2.0 export (conventions in gltf.h). The JSON is written here with the project's own number
// and string helpers: every number is the shortest text of its double, and accessor bounds are
// the exact float32 values the buffer holds, as validators compare them. Under a joint bound the
// rotations are fitted by gltf_joint_bound.cc, which measures the file as glTF evaluates it.
#include "tempokey/core/io/gltf.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <exception>
#include <optional>
#include <set>
#include <stop_token>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "absl/strings/escaping.h"
#include "absl/strings/str_cat.h"
#include "gltf_joint_bound.h"
#include "tempokey/core/io/json.h"
#include "tempokey/core/model/kinematics.h"
#include "tempokey/core/model/numbers.h"
#include "tempokey/core/model/progress.h"
#include "tempokey/core/model/rotation.h"
#include "tempokey/core/model/status.h"
#include "tempokey/core/reduce/quaternion_fit.h"

namespace tempokey::core {
namespace {

using gltf_internal::TranslationKeys;

// ---- the document ----------------------------------------------------------------------------

struct Accessor {
  std::size_t byte_offset = 0;
  std::size_t byte_length = 0;
  std::size_t count = 0;
  std::string_view type;  // SCALAR, VEC3, VEC4
  std::optional<std::pair<float, float>> bounds;  // min and max, for sampler inputs
};

struct Sampler {
  int input = 0;
  int output = 0;
  std::string_view interpolation;
};

struct Target {
  int sampler = 0;
  int node = 0;
  std::string_view path;  // translation, rotation
};

struct Node {
  std::string name;
  Vec3 translation{};
  std::vector<int> children;
};

// Accumulates nodes, float data and animation samplers, then writes .gltf or .glb.
class Document {
 public:
  explicit Document(std::string name) : name_(std::move(name)) {}

  std::vector<Node>& nodes() { return nodes_; }
  std::vector<int>& roots() { return roots_; }

  // A float accessor of `values` (count = values.size() / components).
  int AddAccessor(std::span<const float> values, int components, bool with_bounds) {
    Accessor accessor;
    accessor.byte_offset = buffer_.size();
    accessor.byte_length = values.size() * sizeof(float);
    accessor.count = values.size() / static_cast<std::size_t>(components);
    accessor.type = components == 1 ? "SCALAR" : components == 3 ? "VEC3" : "VEC4";
    if (with_bounds && !values.empty()) {
      const auto [low, high] = std::minmax_element(values.begin(), values.end());
      accessor.bounds = std::make_pair(*low, *high);
    }
    // glTF is little-endian, as are our targets: the floats' bytes as they lie in memory.
    const std::size_t at = buffer_.size();
    buffer_.resize(at + values.size() * sizeof(float));
    if (!values.empty()) {
      std::memcpy(buffer_.data() + at, values.data(), values.size() * sizeof(float));
    }
    accessors_.push_back(accessor);
    return static_cast<int>(accessors_.size()) - 1;
  }

  void AddChannel(int input, int output, std::string_view interpolation, int node,
                  std::string_view path) {
    samplers_.push_back({input, output, interpolation});
    targets_.push_back({static_cast<int>(samplers_.size()) - 1, node, path});
  }

  std::string Serialize(GltfContainer container) const {
    if (container == GltfContainer::kText) {
      return Json(absl::StrCat("data:application/octet-stream;base64,",
                               absl::Base64Escape(buffer_)));
    }
    return Glb();
  }

 private:
  std::string Json(std::optional<std::string> uri) const {
    std::string out = R"({"asset":{"version":"2.0","generator":"tempokey"},"scene":0,"scenes":[{"name":)";
    AppendJsonString(out, name_);
    out += R"(,"nodes":[)";
    AppendInts(out, roots_);
    out += "]}],\"nodes\":[";
    for (std::size_t n = 0; n < nodes_.size(); ++n) {
      if (n > 0) out += ',';
      out += "{\"name\":";
      AppendJsonString(out, nodes_[n].name);
      out += ",\"translation\":[";
      for (int i = 0; i < 3; ++i) {
        if (i > 0) out += ',';
        AppendDouble(out, nodes_[n].translation[i]);
      }
      out += ']';
      if (!nodes_[n].children.empty()) {
        out += ",\"children\":[";
        AppendInts(out, nodes_[n].children);
        out += ']';
      }
      out += '}';
    }
    out += ']';
    if (!samplers_.empty()) {
      out += ",\"animations\":[{\"name\":";
      AppendJsonString(out, name_);
      out += ",\"samplers\":[";
      for (std::size_t s = 0; s < samplers_.size(); ++s) {
        absl::StrAppend(&out, s > 0 ? "," : "", "{\"input\":", samplers_[s].input,
                        ",\"output\":", samplers_[s].output, ",\"interpolation\":\"",
                        AsAbsl(samplers_[s].interpolation), "\"}");
      }
      out += "],\"channels\":[";
      for (std::size_t c = 0; c < targets_.size(); ++c) {
        absl::StrAppend(&out, c > 0 ? "," : "", "{\"sampler\":", targets_[c].sampler,
                        ",\"target\":{\"node\":", targets_[c].node, ",\"path\":\"",
                        AsAbsl(targets_[c].path), "\"}}");
      }
      out += "]}]";
    }
    if (!accessors_.empty()) {
      out += ",\"accessors\":[";
      for (std::size_t a = 0; a < accessors_.size(); ++a) {
        const Accessor& accessor = accessors_[a];
        absl::StrAppend(&out, a > 0 ? "," : "", "{\"bufferView\":", a,
                        ",\"componentType\":5126,\"count\":", accessor.count, ",\"type\":\"",
                        AsAbsl(accessor.type), "\"");
        if (accessor.bounds) {
          out += ",\"min\":[";
          AppendDouble(out, static_cast<double>(accessor.bounds->first));
          out += "],\"max\":[";
          AppendDouble(out, static_cast<double>(accessor.bounds->second));
          out += ']';
        }
        out += '}';
      }
      out += "],\"bufferViews\":[";
      for (std::size_t a = 0; a < accessors_.size(); ++a) {
        absl::StrAppend(&out, a > 0 ? "," : "", "{\"buffer\":0,\"byteOffset\":",
                        accessors_[a].byte_offset, ",\"byteLength\":", accessors_[a].byte_length,
                        "}");
      }
      absl::StrAppend(&out, "],\"buffers\":[{\"byteLength\":", buffer_.size());
      if (uri) {
        out += ",\"uri\":";
        AppendJsonString(out, *uri);
      }
      out += "}]";
    }
    out += "}\n";
    return out;
  }

  static void AppendUint32(std::string& out, std::uint32_t v) {
    for (int i = 0; i < 4; ++i) out += static_cast<char>((v >> (8 * i)) & 0xffu);
  }

  // GLB: 12-byte header, a JSON chunk padded with spaces and a BIN chunk padded with zeros, each
  // to 4 bytes (glTF 2.0, "Binary glTF Layout").
  std::string Glb() const {
    std::string json = Json(std::nullopt);
    while (json.size() % 4 != 0) json += ' ';
    std::string bin = buffer_;
    while (bin.size() % 4 != 0) bin += '\0';
    const std::size_t total = 12 + 8 + json.size() + (bin.empty() ? 0 : 8 + bin.size());
    std::string out;
    out.reserve(total);
    AppendUint32(out, 0x46546C67u);  // "glTF"
    AppendUint32(out, 2);
    AppendUint32(out, static_cast<std::uint32_t>(total));
    AppendUint32(out, static_cast<std::uint32_t>(json.size()));
    AppendUint32(out, 0x4E4F534Au);  // "JSON"
    out += json;
    if (!bin.empty()) {
      AppendUint32(out, static_cast<std::uint32_t>(bin.size()));
      AppendUint32(out, 0x004E4942u);  // "BIN\0"
      out += bin;
    }
    return out;
  }

  static void AppendInts(std::string& out, const std::vector<int>& values) {
    for (std::size_t i = 0; i < values.size(); ++i) absl::StrAppend(&out, i > 0 ? "," : "", values[i]);
  }

  std::string name_;
  std::vector<Node> nodes_;
  std::vector<int> roots_;
  std::vector<Accessor> accessors_;
  std::vector<Sampler> samplers_;
  std::vector<Target> targets_;
  std::string buffer_;
};

// ---- the skeleton ----------------------------------------------------------------------------

// Nodes for the joints (same indices) and their End Sites.
void AddSkeletonNodes(const Clip& clip, Document& document) {
  const std::vector<Joint>& joints = clip.skeleton.joints;
  std::set<std::string> taken;
  for (const Joint& joint : joints) taken.insert(joint.name);
  for (std::size_t j = 0; j < joints.size(); ++j) {
    document.nodes().push_back({joints[j].name, joints[j].offset, {}});
    if (joints[j].parent < 0) {
      document.roots().push_back(static_cast<int>(j));
    } else {
      document.nodes()[static_cast<std::size_t>(joints[j].parent)].children.push_back(
          static_cast<int>(j));
    }
  }
  for (std::size_t j = 0; j < joints.size(); ++j) {
    const std::vector<Vec3>& ends = joints[j].end_sites;
    for (std::size_t e = 0; e < ends.size(); ++e) {
      std::string name = absl::StrCat(joints[j].name, "_end", ends.size() > 1 ? absl::StrCat(e + 1) : "");
      for (int n = 2; taken.count(name) > 0; ++n) name = absl::StrCat(joints[j].name, "_end_", n);
      taken.insert(name);
      document.nodes().push_back({name, ends[e], {}});
      document.nodes()[j].children.push_back(static_cast<int>(document.nodes().size()) - 1);
    }
  }
}

// The position channel of `joint` on each axis, -1 where it has none.
std::array<int, 3> PositionChannels(const Clip& clip, int joint) {
  std::array<int, 3> channels = {-1, -1, -1};
  for (int c : clip.skeleton.joints[static_cast<std::size_t>(joint)].channels) {
    if (IsPosition(clip.channels[static_cast<std::size_t>(c)].kind)) {
      channels[static_cast<std::size_t>(Axis(clip.channels[static_cast<std::size_t>(c)].kind))] = c;
    }
  }
  return channels;
}

bool HasAny(const std::array<int, 3>& channels) {
  return channels[0] >= 0 || channels[1] >= 0 || channels[2] >= 0;
}

// Items (frames, key times) between two looks at the stop token in the loops below: a few
// milliseconds of the costliest, a joint's rotations (three sines and cosines a frame).
constexpr std::size_t kStopCheckItems = std::size_t{1} << 16;
// Translation keys between two looks: each samples three curves (a search and a cubic each).
constexpr std::size_t kStopCheckKeys = std::size_t{1} << 12;

// The source rotation of `rotation`'s joint at every frame: its channels composed in listed
// order, signs made continuous. kCancelled when `stop` is requested (looked at every
// kStopCheckItems frames).
absl::StatusOr<std::vector<Quat>> JointQuaternions(const Clip& clip,
                                                   const JointRotation& rotation,
                                                   const std::stop_token& stop) {
  std::vector<Quat> quats(static_cast<std::size_t>(clip.frame_count));
  for (std::size_t i = 0; i < quats.size(); ++i) {
    if (i % kStopCheckItems == kStopCheckItems - 1) {
      TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    }
    Quat q;
    for (int c : rotation.channels) {
      const Channel& channel = clip.channels[static_cast<std::size_t>(c)];
      q = Multiply(q, AxisRotation(Axis(channel.kind), channel.samples[i]));
    }
    quats[i] = q;
  }
  MakeSignContinuous(quats);
  return quats;
}

void AppendQuat(std::vector<float>& out, const Quat& q) {
  // glTF stores (x, y, z, w).
  out.insert(out.end(), {static_cast<float>(q.x), static_cast<float>(q.y), static_cast<float>(q.z),
                         static_cast<float>(q.w)});
}

absl::Status CheckSkeleton(const Clip& clip) {
  if (clip.skeleton.empty()) {
    return absl::InvalidArgumentError(
        "glTF export needs a skeleton: this clip has plain channels only (no nodes to animate)");
  }
  return absl::OkStatus();
}

absl::Status CheckFloatTimes(const Clip& clip) {
  for (std::int64_t i = 1; i < clip.frame_count; ++i) {
    if (!(static_cast<float>(static_cast<double>(i) * clip.frame_time_seconds) >
          static_cast<float>(static_cast<double>(i - 1) * clip.frame_time_seconds))) {
      return absl::InvalidArgumentError(absl::StrCat(
          "frame time ", clip.frame_time_seconds, " s is too small for glTF's float32 key times: "
          "frames ", i - 1, " and ", i, " fall on the same time"));
    }
  }
  return absl::OkStatus();
}

// ---- keyed translation: exact splits of the keyed curves ---------------------------------------

struct CurvePoint {
  double value = 0.0;
  double in_slope = 0.0;   // per second
  double out_slope = 0.0;
};

constexpr double kUnsetWeight = 1.0 / 3.0;

bool IsWeightedSegment(const Key& a, const Key& b) { return a.out_weight || b.in_weight; }

// Slope (per second) of the segment a-b at `t` inside it.
double SegmentSlope(const Key& a, const Key& b, double t) {
  const double dt = b.time_seconds - a.time_seconds;
  if (!IsWeightedSegment(a, b)) {
    const double s = (t - a.time_seconds) / dt;
    const double d00 = 6 * s * s - 6 * s;
    const double d10 = 3 * s * s - 4 * s + 1;
    const double d01 = -d00;
    const double d11 = 3 * s * s - 2 * s;
    return (d00 * a.value + d10 * dt * a.out_tangent + d01 * b.value + d11 * dt * b.in_tangent) /
           dt;
  }
  const double wa = a.out_weight.value_or(kUnsetWeight) * dt;
  const double wb = b.in_weight.value_or(kUnsetWeight) * dt;
  const double s = SolveBezierParameter(0.0, wa, dt - wb, dt, t - a.time_seconds);
  // Derivatives of the Bezier's x and y in s; dy/dt = y'(s) / x'(s).
  auto derivative = [s](double p0, double p1, double p2, double p3) {
    const double u = 1.0 - s;
    return 3 * u * u * (p1 - p0) + 6 * u * s * (p2 - p1) + 3 * s * s * (p3 - p2);
  };
  const double dx = derivative(0.0, wa, dt - wb, dt);
  const double dy = derivative(a.value, a.value + a.out_tangent * wa, b.value - b.in_tangent * wb,
                               b.value);
  return dy / dx;
}

CurvePoint PointOf(const Curve& curve, double t) {
  const std::vector<Key>& keys = curve.keys;
  CurvePoint point;
  point.value = EvaluateCurve(curve, t);
  if (t < keys.front().time_seconds || t > keys.back().time_seconds) return point;  // held
  const auto next = std::upper_bound(keys.begin(), keys.end(), t,
                                     [](double x, const Key& key) { return x < key.time_seconds; });
  const auto at = next - 1;
  if (at->time_seconds == t) {
    // At a key both sides are the key's own tangents (a Bezier's end slope is its handle's).
    point.in_slope = at->in_tangent;
    point.out_slope = at->out_tangent;
    return point;
  }
  point.in_slope = point.out_slope = SegmentSlope(*at, *next, t);
  return point;
}

// The key times of a joint's translation sampler: every position curve's key times, and every
// source frame inside a weighted segment; distinct as float32. kCancelled when `stop` is
// requested (a joint of millions of frames of keys takes a while).
absl::StatusOr<std::vector<double>> TranslationTimes(const KeyedClip& keyed,
                                                     const std::array<int, 3>& channels,
                                                     const std::stop_token& stop) {
  std::vector<double> times;
  const double frame_time = keyed.layout.frame_time_seconds;
  auto add = [&](double t) -> absl::Status {
    if (times.size() % kStopCheckItems == 0) TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    times.push_back(t);
    return absl::OkStatus();
  };
  for (int c : channels) {
    if (c < 0) continue;
    const std::vector<Key>& keys = keyed.curves[static_cast<std::size_t>(c)].keys;
    for (const Key& key : keys) TEMPOKEY_RETURN_IF_ERROR(add(key.time_seconds));
    for (std::size_t k = 0; k + 1 < keys.size(); ++k) {
      if (!IsWeightedSegment(keys[k], keys[k + 1])) continue;
      const auto first = static_cast<std::int64_t>(std::ceil(keys[k].time_seconds / frame_time));
      for (std::int64_t i = std::max<std::int64_t>(first, 0);
           static_cast<double>(i) * frame_time < keys[k + 1].time_seconds; ++i) {
        TEMPOKEY_RETURN_IF_ERROR(add(static_cast<double>(i) * frame_time));
      }
    }
  }
  // Sorted and each time once, the first of equal ones kept (what a set of them holds: +0 and
  // -0 are one time), then distinct as float32. (The sort is not stopped: about 25 ms for 3 M
  // times.)
  TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
  std::stable_sort(times.begin(), times.end());
  times.erase(std::unique(times.begin(), times.end()), times.end());
  TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
  std::vector<double> distinct;
  for (double t : times) {
    if (distinct.empty() || static_cast<float>(t) > static_cast<float>(distinct.back())) {
      distinct.push_back(t);
    }
  }
  return distinct;
}

absl::Status CheckSameSource(const Clip& source, const KeyedClip& keyed) {
  const Clip& layout = keyed.layout;
  bool same = source.frame_time_seconds == layout.frame_time_seconds &&
              source.frame_count == layout.frame_count && source.skeleton == layout.skeleton &&
              source.channels.size() == layout.channels.size();
  for (std::size_t c = 0; same && c < source.channels.size(); ++c) {
    same = source.channels[c].joint == layout.channels[c].joint &&
           source.channels[c].kind == layout.channels[c].kind;
  }
  if (same) return absl::OkStatus();
  return absl::InvalidArgumentError(
      "the keyed clip does not come from this source clip (skeleton, channels, frame time or "
      "frame count differ): glTF rotations are fitted against the clip that was reduced");
}

}  // namespace

absl::StatusOr<GltfFile> FormatGltfSampled(const Clip& clip, GltfContainer container) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateClip(clip));
  TEMPOKEY_RETURN_IF_ERROR(CheckSkeleton(clip));
  TEMPOKEY_RETURN_IF_ERROR(CheckFloatTimes(clip));
  Document document(clip.name);
  AddSkeletonNodes(clip, document);
  GltfFile file;
  const auto frames = static_cast<std::size_t>(clip.frame_count);
  std::vector<float> times(frames);
  for (std::size_t i = 0; i < frames; ++i) {
    times[i] = static_cast<float>(static_cast<double>(i) * clip.frame_time_seconds);
  }
  const int input = document.AddAccessor(times, 1, true);
  for (std::size_t j = 0; j < clip.skeleton.joints.size(); ++j) {
    const std::array<int, 3> channels = PositionChannels(clip, static_cast<int>(j));
    if (!HasAny(channels)) continue;
    std::vector<float> values;
    values.reserve(3 * frames);
    for (std::size_t i = 0; i < frames; ++i) {
      for (std::size_t axis = 0; axis < 3; ++axis) {
        values.push_back(static_cast<float>(
            channels[axis] >= 0 ? clip.channels[static_cast<std::size_t>(channels[axis])].samples[i]
                                : clip.skeleton.joints[j].offset[axis]));
      }
    }
    document.AddChannel(input, document.AddAccessor(values, 3, false), "LINEAR",
                        static_cast<int>(j), "translation");
    file.stats.translation_keys += static_cast<std::int64_t>(frames);
  }
  for (const JointRotation& rotation : JointRotations(clip)) {
    std::vector<float> values;
    values.reserve(4 * frames);
    const absl::StatusOr<std::vector<Quat>> quats = JointQuaternions(clip, rotation, {});
    for (const Quat& q : *quats) AppendQuat(values, q);  // no stop token: never cancelled
    document.AddChannel(input, document.AddAccessor(values, 4, false), "LINEAR", rotation.joint,
                        "rotation");
    ++file.stats.animated_joints;
    file.stats.rotation_keys += static_cast<std::int64_t>(frames);
    file.stats.rotation_samples += static_cast<std::int64_t>(frames);
  }
  file.bytes = document.Serialize(container);
  return file;
}

// One joint's rotation fitted as glTF keys (FitQuaternionCurve()); errors name the joint.
absl::StatusOr<QuaternionCurve> FitRotation(const Clip& source, const JointRotation& rotation,
                                            double max_angle_degrees,
                                            const std::stop_token& stop) {
  TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
  TEMPOKEY_ASSIGN_OR_RETURN(const std::vector<Quat> quats,
                            JointQuaternions(source, rotation, stop));
  absl::StatusOr<QuaternionCurve> curve =
      FitQuaternionCurve(quats, source.frame_time_seconds, max_angle_degrees, stop);
  if (!curve.ok()) {
    return Annotate(curve.status(),
                    absl::StrCat("joint ", rotation.joint, " (",
                                 source.skeleton.joints[static_cast<std::size_t>(rotation.joint)].name,
                                 ") rotation"));
  }
  return curve;
}

// Working memory of one joint's rotation fit, per frame: its quaternions, their components and
// the fit's buffers (about 100-125 bytes measured), so a few threads on a long clip stay within
// kMaxFitThreadsBytes between them.
constexpr std::int64_t kFitBytesPerFrame = 128;
constexpr std::int64_t kMaxFitThreadsBytes = std::int64_t{1} << 30;

// Every joint's rotation fitted (FitRotation(), rotation r within max_angle_degrees[r]), on up to
// `threads` threads (the calling one among them; fewer when a thread cannot start, and no more
// than keep their working memory within kMaxFitThreadsBytes): the curves in joint order, or the
// first error in joint order, as one thread fitting the joints in turn gives. Joints are taken in
// order, and none after a failed one is started, so every joint before the first failure is
// fitted. An exception (an allocation's) from a joint's fit is rethrown here, once every thread
// has ended, when no joint before it failed.
absl::StatusOr<std::vector<QuaternionCurve>> FitRotations(
    const Clip& source, const std::vector<JointRotation>& rotations,
    std::span<const double> max_angle_degrees, int threads, const std::stop_token& stop) {
  const std::size_t count = rotations.size();
  std::vector<absl::StatusOr<QuaternionCurve>> curves(count, absl::UnknownError("not fitted"));
  std::vector<std::exception_ptr> thrown(count);
  std::atomic<std::size_t> next{0};
  std::atomic<std::size_t> first_failure{count};
  auto work = [&] {
    for (std::size_t r = next++; r < count && r < first_failure.load(); r = next++) {
      try {
        curves[r] = FitRotation(source, rotations[r], max_angle_degrees[r], stop);
      } catch (...) {
        thrown[r] = std::current_exception();
      }
      if (curves[r].ok()) continue;
      std::size_t seen = first_failure.load();
      while (r < seen && !first_failure.compare_exchange_weak(seen, r)) {
      }
    }
  };
  const std::int64_t memory_threads = std::max<std::int64_t>(
      1, kMaxFitThreadsBytes / std::max<std::int64_t>(1, source.frame_count * kFitBytesPerFrame));
  const std::size_t wanted = static_cast<std::size_t>(
      std::min<std::int64_t>(std::max(1, threads), memory_threads));
  const std::size_t helper_count = std::min(wanted, std::max<std::size_t>(count, 1)) - 1;
  {
    std::vector<std::jthread> helpers;  // joined on every way out of this block
    try {
      helpers.reserve(helper_count);
      for (std::size_t t = 0; t < helper_count; ++t) helpers.emplace_back(work);
    } catch (...) {
      // The threads started so far, and this one, share the joints.
    }
    work();
  }
  std::vector<QuaternionCurve> fitted;
  fitted.reserve(count);
  for (std::size_t r = 0; r < count; ++r) {
    if (thrown[r]) std::rethrow_exception(thrown[r]);
    if (!curves[r].ok()) return curves[r].status();
    fitted.push_back(*std::move(curves[r]));
  }
  return fitted;
}

namespace {

// A keyed channel: `output` holds in-tangent, value and out-tangent (`components` floats each)
// per key of `input`, written CUBICSPLINE; a channel of one key (a one-frame clip) is written
// LINEAR with its value alone, since glTF says a CUBICSPLINE sampler "MUST" have "at least two
// keyframes" (animation.sampler.schema.json) and one key holds its value either way.
void AddKeyedChannel(Document& document, std::span<const float> input,
                     std::span<const float> output, int components, int node,
                     std::string_view path) {
  const int in = document.AddAccessor(input, 1, true);
  if (input.size() < 2) {
    const auto width = static_cast<std::size_t>(components);
    document.AddChannel(in, document.AddAccessor(output.subspan(width, width * input.size()),
                                                 components, false),
                        "LINEAR", node, path);
    return;
  }
  document.AddChannel(in, document.AddAccessor(output, components, false), "CUBICSPLINE", node,
                      path);
}

}  // namespace

absl::StatusOr<GltfFile> FormatGltfKeyed(const Clip& source, const KeyedClip& keyed,
                                         const GltfKeyedOptions& options, GltfContainer container,
                                         std::stop_token stop) {
  TEMPOKEY_RETURN_IF_ERROR(ValidateClip(source));
  TEMPOKEY_RETURN_IF_ERROR(ValidateKeyedClip(keyed));
  TEMPOKEY_RETURN_IF_ERROR(CheckSameSource(source, keyed));
  TEMPOKEY_RETURN_IF_ERROR(CheckSkeleton(source));
  TEMPOKEY_RETURN_IF_ERROR(CheckFloatTimes(source));
  if (!std::isfinite(options.max_rotation_error_degrees) ||
      options.max_rotation_error_degrees <= 0.0) {
    return absl::InvalidArgumentError(
        absl::StrCat("glTF rotation bound must be finite and > 0 degrees, got ",
                     DescribeDouble(options.max_rotation_error_degrees)));
  }
  if (options.joint_tolerance) {
    TEMPOKEY_RETURN_IF_ERROR(ValidateJointTolerance(*options.joint_tolerance));
  }
  Document document(keyed.layout.name);
  AddSkeletonNodes(source, document);
  GltfFile file;
  std::vector<TranslationKeys> translations;
  for (std::size_t j = 0; j < source.skeleton.joints.size(); ++j) {
    const std::array<int, 3> channels = PositionChannels(source, static_cast<int>(j));
    if (!HasAny(channels)) continue;
    TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
    TEMPOKEY_ASSIGN_OR_RETURN(const std::vector<double> times,
                              TranslationTimes(keyed, channels, stop));
    TranslationKeys& keys = translations.emplace_back();
    keys.joint = static_cast<int>(j);
    std::vector<float>& input = keys.input;
    std::vector<float>& output = keys.output;
    for (std::size_t i = 0; i < times.size(); ++i) {
      if (i % kStopCheckKeys == kStopCheckKeys - 1) {
        TEMPOKEY_RETURN_IF_ERROR(CheckNotCancelled(stop));
      }
      const double t = times[i];
      input.push_back(static_cast<float>(t));
      std::array<CurvePoint, 3> points;
      for (std::size_t axis = 0; axis < 3; ++axis) {
        points[axis] = channels[axis] >= 0
                           ? PointOf(keyed.curves[static_cast<std::size_t>(channels[axis])], t)
                           : CurvePoint{source.skeleton.joints[j].offset[axis], 0.0, 0.0};
      }
      for (const CurvePoint& p : points) output.push_back(static_cast<float>(p.in_slope));
      for (const CurvePoint& p : points) output.push_back(static_cast<float>(p.value));
      for (const CurvePoint& p : points) output.push_back(static_cast<float>(p.out_slope));
    }
    file.stats.translation_keys += static_cast<std::int64_t>(times.size());
  }
  const std::vector<JointRotation> rotations = JointRotations(source);
  std::vector<QuaternionCurve> curves;
  if (options.joint_tolerance) {
    auto fit_rotations = [&](const std::vector<JointRotation>& to_fit,
                             std::span<const double> max_angle_degrees) {
      return FitRotations(source, to_fit, max_angle_degrees, options.threads, stop);
    };
    auto source_rotations = [&](const JointRotation& rotation) {
      return JointQuaternions(source, rotation, stop);
    };
    TEMPOKEY_ASSIGN_OR_RETURN(curves, gltf_internal::FitRotationsWithinJointBound(
                                          source, rotations, translations, options, fit_rotations,
                                          source_rotations, file.stats, stop));
  } else {
    const std::vector<double> bounds(rotations.size(), options.max_rotation_error_degrees);
    TEMPOKEY_ASSIGN_OR_RETURN(curves,
                              FitRotations(source, rotations, bounds, options.threads, stop));
  }
  for (const TranslationKeys& keys : translations) {
    AddKeyedChannel(document, keys.input, keys.output, 3, keys.joint, "translation");
  }
  for (std::size_t r = 0; r < rotations.size(); ++r) {
    const JointRotation& rotation = rotations[r];
    const QuaternionCurve& curve = curves[r];
    std::vector<float> input;
    std::vector<float> output;
    for (const QuaternionKey& key : curve.keys) {
      input.push_back(static_cast<float>(key.time_seconds));
      AppendQuat(output, key.in_tangent);
      AppendQuat(output, key.value);
      AppendQuat(output, key.out_tangent);
    }
    AddKeyedChannel(document, input, output, 4, rotation.joint, "rotation");
    ++file.stats.animated_joints;
    file.stats.rotation_keys += static_cast<std::int64_t>(curve.keys.size());
    file.stats.rotation_samples += source.frame_count;
  }
  file.bytes = document.Serialize(container);
  return file;
}

}  // namespace tempokey::core
