// A minimal BVH reader for the export checks, written apart from tempokey's C++ reader: the
// hierarchy (names, offsets, channel lists, parents, end sites' offsets) and the motion rows. Each
// joint's local transform per frame follows the BVH convention: translation = the offset with each
// position channel replacing its axis; rotation = the rotation channels composed in listed order
// (intrinsic, left to right: `Zrotation Xrotation Yrotation` is Rz·Rx·Ry), built here with three.js
// quaternions from axis angles.
import * as THREE from 'three';

export function parseBvh(text) {
  const tokens = text.split(/\s+/).filter((t) => t.length > 0);
  let at = 0;
  const next = () => tokens[at++];
  const joints = [];
  const stack = [];
  let channelCount = 0;
  if (next() !== 'HIERARCHY') throw new Error('not a BVH file: no HIERARCHY');
  while (at < tokens.length) {
    const word = next();
    if (word === 'ROOT' || word === 'JOINT') {
      const joint = {
        name: next(), parent: stack.length ? stack[stack.length - 1] : -1,
        offset: [0, 0, 0], channels: [], endSites: [],
      };
      joints.push(joint);
      stack.push(joints.length - 1);
      if (next() !== '{') throw new Error(`expected { after ${joint.name}`);
    } else if (word === 'End') {
      next();  // Site
      next();  // {
      next();  // OFFSET
      const site = [Number(next()), Number(next()), Number(next())];
      joints[stack[stack.length - 1]].endSites.push(site);
      next();  // }
    } else if (word === 'OFFSET') {
      const joint = joints[stack[stack.length - 1]];
      joint.offset = [Number(next()), Number(next()), Number(next())];
    } else if (word === 'CHANNELS') {
      const joint = joints[stack[stack.length - 1]];
      const n = Number(next());
      for (let i = 0; i < n; ++i) joint.channels.push({ kind: next(), column: channelCount++ });
    } else if (word === '}') {
      stack.pop();
    } else if (word === 'MOTION') {
      break;
    } else {
      throw new Error(`unexpected word ${word}`);
    }
  }
  if (next() !== 'Frames:') throw new Error('expected Frames:');
  const frames = Number(next());
  if (next() !== 'Frame' || next() !== 'Time:') throw new Error('expected Frame Time:');
  const frameTime = Number(next());
  const rows = [];
  for (let f = 0; f < frames; ++f) {
    const row = new Float64Array(channelCount);
    for (let c = 0; c < channelCount; ++c) row[c] = Number(next());
    rows.push(row);
  }
  return { joints, frames, frameTime, rows };
}

const AXES = {
  X: new THREE.Vector3(1, 0, 0), Y: new THREE.Vector3(0, 1, 0), Z: new THREE.Vector3(0, 0, 1),
};

// The local rotation of `joint` at `frame` (a THREE.Quaternion).
export function localRotation(bvh, joint, frame) {
  const q = new THREE.Quaternion();
  const axisQ = new THREE.Quaternion();
  for (const channel of joint.channels) {
    if (!channel.kind.endsWith('rotation')) continue;
    const degrees = bvh.rows[frame][channel.column];
    axisQ.setFromAxisAngle(AXES[channel.kind[0]], (degrees * Math.PI) / 180);
    q.multiply(axisQ);
  }
  return q;
}

// The local translation of `joint` at `frame` ([x, y, z]).
export function localTranslation(bvh, joint, frame) {
  const t = joint.offset.slice();
  for (const channel of joint.channels) {
    if (!channel.kind.endsWith('position')) continue;
    t['XYZ'.indexOf(channel.kind[0])] = bvh.rows[frame][channel.column];
  }
  return t;
}

export function hasRotation(joint) {
  return joint.channels.some((c) => c.kind.endsWith('rotation'));
}
export function hasPosition(joint) {
  return joint.channels.some((c) => c.kind.endsWith('position'));
}
