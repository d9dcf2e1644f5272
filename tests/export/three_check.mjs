// Plays a glTF written by tempokey with three.js (GLTFLoader + AnimationMixer, the code a web
// viewer runs) and compares every joint's local rotation and translation with the source BVH at
// every source frame.
//
//   node three_check.mjs SOURCE.bvh FILE.gltf|FILE.glb
//
// Prints one JSON object: {"file", "frames", "joints", "animated_joints",
// "max_rotation_error_degrees", "worst_rotation": {"joint", "frame"},
// "max_translation_error", "worst_translation": {"joint", "frame"}, "rotation_keys",
// "rotation_tracks"}. Rotation error: the angle of the rotation between three.js's pose and the
// source's; translation error: the largest component difference, file units. Exit 1 on errors.
import * as THREE from 'three';
import { localRotation, localTranslation } from './bvh_source.mjs';
import { readCheckInputs } from './check_inputs.mjs';

async function main() {
  const { bvh, gltf, gltfPath } = await readCheckInputs('three_check.mjs');
  const clip = gltf.animations[0];
  const scene = gltf.scene;
  const mixer = new THREE.AnimationMixer(scene);
  const action = mixer.clipAction(clip);
  action.setLoop(THREE.LoopOnce, 1);
  action.clampWhenFinished = true;
  action.play();

  const nodes = bvh.joints.map((joint) => {
    const node = scene.getObjectByName(THREE.PropertyBinding.sanitizeNodeName(joint.name));
    if (!node) throw new Error(`no node for joint ${joint.name}`);
    return node;
  });
  const result = {
    file: gltfPath, frames: bvh.frames, joints: bvh.joints.length,
    animated_joints: 0, max_rotation_error_degrees: 0, worst_rotation: null,
    max_translation_error: 0, worst_translation: null, rotation_keys: 0, rotation_tracks: 0,
  };
  for (const track of clip.tracks) {
    if (track.name.endsWith('.quaternion')) {
      result.rotation_tracks += 1;
      result.rotation_keys += track.times.length;
    }
  }
  result.animated_joints = result.rotation_tracks;
  const source = new THREE.Quaternion();
  const played = new THREE.Quaternion();
  for (let frame = 0; frame < bvh.frames; ++frame) {
    mixer.setTime(frame * bvh.frameTime);
    bvh.joints.forEach((joint, j) => {
      source.copy(localRotation(bvh, joint, frame));
      // The node's rotation is its quaternion's direction: LINEAR keys are float32 quaternions
      // whose norm is 1 only to ~1e-7, and angleTo's acos would turn that into ~0.05 degrees.
      played.copy(nodes[j].quaternion).normalize();
      const angle = (played.angleTo(source) * 180) / Math.PI;
      if (angle > result.max_rotation_error_degrees) {
        result.max_rotation_error_degrees = angle;
        result.worst_rotation = { joint: joint.name, frame };
      }
      const t = localTranslation(bvh, joint, frame);
      const p = nodes[j].position;
      const error = Math.max(Math.abs(p.x - t[0]), Math.abs(p.y - t[1]), Math.abs(p.z - t[2]));
      if (error > result.max_translation_error) {
        result.max_translation_error = error;
        result.worst_translation = { joint: joint.name, frame };
      }
    });
  }
  process.stdout.write(`${JSON.stringify(result)}\n`);
}

main().catch((error) => {
  process.stderr.write(`three_check: ${error.stack || error}\n`);
  process.exit(1);
});
