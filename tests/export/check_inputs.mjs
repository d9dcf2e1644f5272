// The inputs of the checks that play a tempokey glTF beside its source BVH (three_check.mjs,
// world_check.mjs): the command line, the source read by this folder's own reader, and the glTF
// loaded by three.js's GLTFLoader with exactly one animation.
import { readFileSync } from 'node:fs';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';
import { parseBvh } from './bvh_source.mjs';

// three.js's FileLoader (which GLTFLoader uses for the embedded data: URI buffer, through node's
// fetch) reports progress with the browser's ProgressEvent, which node lacks.
globalThis.ProgressEvent ??= class ProgressEvent extends Event {
  constructor(type, init = {}) {
    super(type);
    Object.assign(this, init);
  }
};

function loadGltf(path) {
  const bytes = readFileSync(path);
  const data = path.endsWith('.glb')
    ? bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength)
    : bytes.toString('utf8');
  return new Promise((resolve, reject) => {
    new GLTFLoader().parse(data, '', resolve, reject);
  });
}

// `node SCRIPT SOURCE.bvh FILE.gltf|FILE.glb`: {bvh, gltf, gltfPath}; throws with the usage or
// the reason.
export async function readCheckInputs(script) {
  const [bvhPath, gltfPath] = process.argv.slice(2);
  if (!bvhPath || !gltfPath) throw new Error(`usage: ${script} SOURCE.bvh FILE.gltf`);
  const bvh = parseBvh(readFileSync(bvhPath, 'utf8'));
  const gltf = await loadGltf(gltfPath);
  if (gltf.animations.length !== 1) throw new Error(`expected 1 animation, got ${gltf.animations.length}`);
  return { bvh, gltf, gltfPath };
}
