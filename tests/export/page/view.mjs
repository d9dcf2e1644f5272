// Opens /clip.gltf with three.js's GLTFLoader, poses it with an AnimationMixer at ?t=SECONDS and
// draws the skeleton: a line from every node to its parent. WebGL when the browser has it,
// otherwise the same projection drawn on a 2D canvas. The title and #status report what was
// drawn ("ready bones=N renderer=webgl t=1.5").
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';

const status = document.getElementById('status');
const canvas = document.getElementById('view');

function report(text) {
  status.textContent = text;
  document.title = text;
}

function bonesOf(root) {
  const segments = [];
  root.updateMatrixWorld(true);
  root.traverse((node) => {
    if (node === root || !node.parent || node.parent === root) return;
    const a = new THREE.Vector3().setFromMatrixPosition(node.parent.matrixWorld);
    const b = new THREE.Vector3().setFromMatrixPosition(node.matrixWorld);
    segments.push([a, b]);
  });
  return segments;
}

function cameraFor(segments) {
  const box = new THREE.Box3();
  for (const [a, b] of segments) box.expandByPoint(a).expandByPoint(b);
  const center = box.getCenter(new THREE.Vector3());
  const size = box.getSize(new THREE.Vector3()).length();
  const camera = new THREE.PerspectiveCamera(35, canvas.width / canvas.height, size / 100, size * 10);
  camera.position.set(center.x + size * 0.6, center.y + size * 0.25, center.z + size * 1.4);
  camera.lookAt(center);
  camera.updateMatrixWorld(true);
  return camera;
}

function drawWebGl(segments, camera) {
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
  renderer.setClearColor(0xf4f4f0);
  const positions = [];
  for (const [a, b] of segments) positions.push(a.x, a.y, a.z, b.x, b.y, b.z);
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.Float32BufferAttribute(positions, 3));
  const scene = new THREE.Scene();
  scene.add(new THREE.LineSegments(geometry, new THREE.LineBasicMaterial({ color: 0x1f4e9c })));
  const joints = new THREE.Points(geometry, new THREE.PointsMaterial({ color: 0xc0392b, size: 5, sizeAttenuation: false }));
  scene.add(joints);
  renderer.render(scene, camera);
}

function draw2d(segments, camera) {
  const context = canvas.getContext('2d');
  context.fillStyle = '#f4f4f0';
  context.fillRect(0, 0, canvas.width, canvas.height);
  const toScreen = (p) => {
    const v = p.clone().project(camera);
    return [(v.x + 1) * 0.5 * canvas.width, (1 - v.y) * 0.5 * canvas.height];
  };
  context.strokeStyle = '#1f4e9c';
  context.lineWidth = 3;
  for (const [a, b] of segments) {
    const [ax, ay] = toScreen(a);
    const [bx, by] = toScreen(b);
    context.beginPath();
    context.moveTo(ax, ay);
    context.lineTo(bx, by);
    context.stroke();
  }
}

async function main() {
  const t = Number(new URLSearchParams(location.search).get('t') ?? '0');
  const gltf = await new GLTFLoader().loadAsync('/clip.gltf');
  const mixer = new THREE.AnimationMixer(gltf.scene);
  const action = mixer.clipAction(gltf.animations[0]);
  action.setLoop(THREE.LoopOnce, 1);
  action.clampWhenFinished = true;
  action.play();
  mixer.setTime(t);
  const segments = bonesOf(gltf.scene);
  const camera = cameraFor(segments);
  let renderer = 'webgl';
  try {
    drawWebGl(segments, camera);
  } catch (error) {
    renderer = '2d';
    draw2d(segments, camera);
  }
  report(`ready bones=${segments.length} renderer=${renderer} t=${t}`);
}

main().catch((error) => report(`failed ${error}`));
