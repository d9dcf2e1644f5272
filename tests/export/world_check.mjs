// Places every joint and end site of a glTF written by tempokey with three.js (GLTFLoader,
// AnimationMixer and the scene graph's own matrices, the code a web viewer runs) and of the source
// BVH (this folder's own reader, posed in a three.js scene graph of its own) at every source
// frame, and measures how far apart they are: a world-space bound checked with forward kinematics
// that is not tempokey's.
//
//   node world_check.mjs SOURCE.bvh FILE.gltf|FILE.glb
//
// Prints one JSON object: {"file", "frames", "points", "max_world_error", "worst": {"point",
// "frame"}}; distances in file units. End sites are placed by their joint's world matrix in both
// scenes (their offsets are the source's). Exit 1 on errors.
import * as THREE from 'three';
import { localRotation, localTranslation } from './bvh_source.mjs';
import { readCheckInputs } from './check_inputs.mjs';

// The source skeleton as a three.js hierarchy: one Object3D per joint.
function sourceScene(bvh) {
  const root = new THREE.Group();
  const objects = bvh.joints.map(() => new THREE.Object3D());
  bvh.joints.forEach((joint, j) => {
    (joint.parent < 0 ? root : objects[joint.parent]).add(objects[j]);
  });
  return { root, objects };
}

// Every point's world position: joints, then each joint's end sites.
function worldPoints(bvh, objects, out) {
  let at = 0;
  bvh.joints.forEach((joint, j) => {
    objects[j].getWorldPosition(out[at++]);
    for (const site of joint.endSites) {
      out[at++].set(site[0], site[1], site[2]).applyMatrix4(objects[j].matrixWorld);
    }
  });
}

async function main() {
  const { bvh, gltf, gltfPath } = await readCheckInputs('world_check.mjs');
  const mixer = new THREE.AnimationMixer(gltf.scene);
  const action = mixer.clipAction(gltf.animations[0]);
  action.setLoop(THREE.LoopOnce, 1);
  action.clampWhenFinished = true;
  action.play();
  const played = bvh.joints.map((joint) => {
    const node = gltf.scene.getObjectByName(THREE.PropertyBinding.sanitizeNodeName(joint.name));
    if (!node) throw new Error(`no node for joint ${joint.name}`);
    return node;
  });
  const names = [];
  for (const joint of bvh.joints) {
    names.push(joint.name);
    joint.endSites.forEach((_, k) => names.push(`${joint.name} end site ${k}`));
  }
  const source = sourceScene(bvh);
  const want = names.map(() => new THREE.Vector3());
  const got = names.map(() => new THREE.Vector3());
  const result = {
    file: gltfPath, frames: bvh.frames, points: names.length, max_world_error: 0, worst: null,
  };
  for (let frame = 0; frame < bvh.frames; ++frame) {
    bvh.joints.forEach((joint, j) => {
      source.objects[j].quaternion.copy(localRotation(bvh, joint, frame));
      source.objects[j].position.fromArray(localTranslation(bvh, joint, frame));
    });
    source.root.updateMatrixWorld(true);
    worldPoints(bvh, source.objects, want);
    mixer.setTime(frame * bvh.frameTime);
    gltf.scene.updateMatrixWorld(true);
    worldPoints(bvh, played, got);
    names.forEach((name, p) => {
      const error = got[p].distanceTo(want[p]);
      if (error > result.max_world_error) {
        result.max_world_error = error;
        result.worst = { point: name, frame };
      }
    });
  }
  process.stdout.write(`${JSON.stringify(result)}\n`);
}

main().catch((error) => {
  process.stderr.write(`world_check: ${error.stack || error}\n`);
  process.exit(1);
});
