// Skeleton preview: the source and the retimed result side by side (three.js from Debian's
// libjs-three: BVHLoader, SkeletonHelper, OrbitControls), both driven by one clock in output
// frames. Output frame j shows the result's frame j and the source at τ_j, the source time the
// server's time map gives for that frame (PlanRetime), so the two skeletons hold the same pose
// when the retime is right. Play runs at 1× (one output frame per output frame time); step
// moves one frame; the scrub bar picks any frame.
import * as THREE from '/three/build/three.module.js';
import {BVHLoader} from '/three/examples/jsm/loaders/BVHLoader.js';
import {OrbitControls} from '/three/examples/jsm/controls/OrbitControls.js';

const SOURCE_COLOUR = 0x64748b;
const RESULT_COLOUR = 0xea580c;

// The nodes of a BVH `text`'s hierarchy (the lines before its MOTION line) in the file's order,
// which is the order of BVHLoader's bones: {kind: 'joint' (ROOT or JOINT) or 'end' (End Site),
// name, offset: [x, y, z], axes: the axes (0 x, 1 y, 2 z) its position channels hold}.
function hierarchyOf(text) {
  const nodes = [];
  let node = null;
  for (const line of text.split(/\r\n|\r|\n/)) {
    const words = line.trim().split(/\s+/);
    if (words[0] === 'MOTION' && words.length === 1) break;
    if (words[0] === 'ROOT' || words[0] === 'JOINT' || words[0] === 'End') {
      node = {kind: words[0] === 'End' ? 'end' : 'joint', name: words[1] || '', offset: [0, 0, 0], axes: []};
      nodes.push(node);
    } else if (words[0] === 'OFFSET' && node) {
      node.offset = words.slice(1, 4).map(Number);
    } else if (words[0] === 'CHANNELS' && node) {
      for (const name of words.slice(2)) {
        const axis = ['Xposition', 'Yposition', 'Zposition'].indexOf(name);
        if (axis >= 0) node.axes.push(axis);
      }
    }
  }
  return nodes;
}

// BVHLoader adds each joint's OFFSET to its position channels (three.js r111's BVHLoader.js,
// Debian's libjs-three: "the animation system animates the position property, so we have to add
// the joint offset to all values"). tempokey reads a position channel as replacing the OFFSET on
// its axis (README "File formats"), as Blender's BVH import does and as the Bandai captures need:
// each of their joints has six channels holding its offset, so with the offset added every bone
// was drawn twice as long. Takes the offset back out of the axes that have a channel. BVHLoader
// makes a position track, then a quaternion track, for each ROOT and JOINT in the file's order:
// `joints` are those nodes, in that order.
function replaceOffsetsByPositionChannels(tracks, joints) {
  joints.forEach((joint, j) => {
    const track = tracks[2 * j];
    if (!track) return;
    for (const axis of joint.axes) {
      for (let i = axis; i < track.values.length; i += 3) track.values[i] -= joint.offset[axis];
    }
  });
}

// BVHLoader reads one ROOT (three.js r111: "MOTION expected" after it, then a track without
// keyframes throws); tempokey writes one ROOT per root joint, as a CSV's joints come back (every
// one a root). Several roots become the joints of one added root without channels, named apart
// from every joint.
function withOneRoot(text) {
  const lines = text.split(/\r\n|\r|\n/);
  const motion = lines.findIndex((line) => line.trim() === 'MOTION');
  const hierarchy = motion < 0 ? lines : lines.slice(0, motion);
  const roots = hierarchy.filter((line) => /^\s*ROOT\s/.test(line)).length;
  if (roots < 2 || motion < 0) return text;
  const names = new Set(hierarchy.map((line) => line.trim().split(/\s+/)[1]));
  let name = 'tempokey_roots';
  while (names.has(name)) name += '_';
  const start = lines.findIndex((line) => line.trim() === 'HIERARCHY');
  return [
    ...lines.slice(0, start + 1), `ROOT ${name}`, '{', 'OFFSET 0 0 0', 'CHANNELS 0',
    ...lines.slice(start + 1, motion).map((line) => line.replace(/^(\s*)ROOT(\s)/, '$1JOINT$2')),
    '}', ...lines.slice(motion),
  ].join('\n');
}

// A skeleton parsed by BVHLoader, with a pose setter.
class Figure {
  constructor(bvhText, colour, scene) {
    const text = withOneRoot(bvhText);
    const parsed = new BVHLoader().parse(text);
    const nodes = hierarchyOf(text);
    const joints = nodes.filter((node) => node.kind === 'joint');
    replaceOffsetsByPositionChannels(parsed.clip.tracks, joints);
    this.bones = parsed.skeleton.bones;
    this.root = this.bones[0];
    this.group = new THREE.Group();
    this.group.add(this.root);
    scene.add(this.group);
    this.helper = new THREE.SkeletonHelper(this.root);
    this.helper.material.color.setHex(colour);
    this.helper.material.linewidth = 2;
    scene.add(this.helper);
    // A position and a quaternion track per ROOT and JOINT, in the file's order (not by name:
    // a joint may be named like BVHLoader's end sites, "ENDSITE").
    const jointBones = this.bones.filter((_, i) => nodes[i] && nodes[i].kind === 'joint');
    this.tracks = parsed.clip.tracks.map((track, t) => ({
      bone: jointBones[Math.floor(t / 2)],
      property: t % 2 === 0 ? 'position' : 'quaternion',
      track,
      interpolant: track.createInterpolant(),
    }));
    this.times = parsed.clip.tracks[0].times;  // Float32Array of i * frame time
    this.frameCount = this.times.length;
    const geometry = new THREE.SphereBufferGeometry(1, 8, 6);
    const material = new THREE.MeshBasicMaterial({color: colour});
    this.joints = this.bones.map((bone) => {
      const mesh = new THREE.Mesh(geometry, material);
      bone.add(mesh);
      return mesh;
    });
  }
  setJointSize(size) {
    for (const mesh of this.joints) mesh.scale.setScalar(size);
  }
  // The pose at `seconds` (three.js's interpolants: linear positions, slerped rotations).
  poseAt(seconds) {
    for (const {bone, property, interpolant} of this.tracks) {
      if (!bone) continue;
      const value = interpolant.evaluate(seconds);
      if (property === 'position') bone.position.fromArray(value);
      else bone.quaternion.fromArray(value);
    }
  }
  // Exactly frame `j` (its stored key time, so no interpolation weight at all).
  poseAtFrame(j) {
    this.poseAt(this.times[Math.min(Math.max(j, 0), this.frameCount - 1)]);
  }
  dispose(scene) {
    scene.remove(this.group);
    scene.remove(this.helper);
  }
}

export class Preview {
  constructor(container, {onFrame}) {
    this.container = container;
    this.onFrame = onFrame;
    this.frame = 0;
    this.playing = false;
    this.source = null;
    this.result = null;
    this.plan = null;
    this.spacing = 0;
    try {
      this.renderer = new THREE.WebGLRenderer({antialias: true, preserveDrawingBuffer: true});
    } catch (error) {
      container.textContent = 'This browser has no WebGL: the skeleton preview is off.';
      return;
    }
    this.renderer.setPixelRatio(window.devicePixelRatio || 1);
    this.renderer.setClearColor(0xf8fafc);
    container.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.1, 10000);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.addEventListener('change', () => this.render());
    this.grid = null;
    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
  }

  resize() {
    if (!this.renderer) return;
    const w = this.container.clientWidth;
    const h = this.container.clientHeight;
    if (!w || !h) return;
    this.renderer.setSize(w, h);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.render();
  }

  // The source clip (BVH text, as the server writes it).
  // Text BVHLoader cannot read throws, the figures shown before kept.
  setSource(text) {
    if (!this.renderer) return;
    const source = new Figure(text, SOURCE_COLOUR, this.scene);
    if (this.source) this.source.dispose(this.scene);
    if (this.result) this.result.dispose(this.scene);
    this.result = null;
    this.source = source;
    this.source.poseAtFrame(0);
    this.frameCamera();
    this.showFrame(0);
  }

  // No clip: the figures go (a new clip's, if it has a skeleton, come with setSource).
  clear() {
    this.pause();
    if (this.source) this.source.dispose(this.scene);
    if (this.result) this.result.dispose(this.scene);
    this.source = null;
    this.result = null;
    this.plan = null;
    this.frame = 0;
    if (this.grid) {
      this.scene.remove(this.grid);
      this.grid = null;
    }
    for (const name of ['outputFrame', 'sourceSeconds', 'resultRoot', 'sourceRoot', 'sourcePoints', 'resultPoints']) delete this.container.dataset[name];
    this.render();
  }

  // The retimed result (BVH text) and the plan whose map gives τ_j for its frames. Text BVHLoader
  // cannot read throws, the figures shown before kept.
  setResult(text, plan) {
    if (!this.renderer || !this.source) return;
    const result = new Figure(text, RESULT_COLOUR, this.scene);
    if (this.result) this.result.dispose(this.scene);
    this.result = result;
    this.result.group.position.x = this.spacing;
    this.result.setJointSize(this.jointSize);
    this.plan = plan;
    this.showFrame(Math.min(this.frame, this.frameCount() - 1));
  }

  frameCount() {
    if (this.result) return this.result.frameCount;
    return this.source ? this.source.frameCount : 0;
  }

  // The source time shown with output frame j: the server's τ_j, or frame j itself without a
  // result.
  sourceSeconds(j) {
    if (this.result && this.plan && this.plan.sourceTimeSeconds.length === this.result.frameCount) {
      return this.plan.sourceTimeSeconds[j];
    }
    return this.source ? this.source.times[Math.min(j, this.source.frameCount - 1)] : 0;
  }

  frameCamera() {
    this.scene.updateMatrixWorld(true);
    const box = new THREE.Box3();
    const point = new THREE.Vector3();
    for (const bone of this.source.bones) box.expandByPoint(bone.getWorldPosition(point));
    const size = box.getSize(new THREE.Vector3());
    const height = Math.max(size.y, size.x, size.z, 1e-3);
    this.spacing = height * 0.9;
    this.jointSize = height * 0.012;
    this.source.setJointSize(this.jointSize);
    if (this.grid) this.scene.remove(this.grid);
    this.grid = new THREE.GridHelper(height * 8, 16, 0xcbd5e1, 0xe2e8f0);
    this.grid.position.y = box.min.y;
    this.scene.add(this.grid);
    const center = box.getCenter(new THREE.Vector3());
    center.x += this.spacing / 2;
    this.controls.target.copy(center);
    this.camera.position.set(center.x + height * 0.4, center.y + height * 0.7, center.z + height * 2.4);
    this.camera.near = height / 100;
    this.camera.far = height * 100;
    this.camera.updateProjectionMatrix();
    this.controls.update();
  }

  showFrame(j) {
    if (!this.source) return;
    const count = this.frameCount();
    this.frame = Math.min(Math.max(Math.round(j), 0), count - 1);
    const sourceSeconds = this.sourceSeconds(this.frame);
    this.source.poseAt(sourceSeconds);
    if (this.result) this.result.poseAtFrame(this.frame);
    this.render();
    const root = (this.result || this.source).root.position;
    this.container.dataset.outputFrame = String(this.frame);
    this.container.dataset.sourceSeconds = String(sourceSeconds);
    this.container.dataset.resultRoot = this.result ? [root.x, root.y, root.z].join(',') : '';
    this.container.dataset.sourceRoot = [this.source.root.position.x, this.source.root.position.y,
      this.source.root.position.z].join(',');
    // Every bone's place in the scene (joints and end sites in the file's order), for checks.
    this.scene.updateMatrixWorld(true);
    const points = (figure) => figure.bones.map((bone) => bone.getWorldPosition(new THREE.Vector3()).toArray().join(',')).join(';');
    this.container.dataset.sourcePoints = points(this.source);
    this.container.dataset.resultPoints = this.result ? points(this.result) : '';
    this.onFrame(this.frame, sourceSeconds);
  }

  step(delta) {
    this.pause();
    this.showFrame(this.frame + delta);
  }

  // Plays at 1× from the current frame: frame j is shown at j output frame times after start.
  play() {
    if (!this.source || this.playing) return;
    const frameTime = this.result ? this.result.times[1] - this.result.times[0] || 1 / 30 : 1 / 30;
    const exact = this.plan ? this.plan.outputFrameTimeSeconds : frameTime;
    if (this.frame >= this.frameCount() - 1) this.frame = 0;
    this.playing = true;
    const start = performance.now();
    const first = this.frame;
    const tick = (now) => {
      if (!this.playing) return;
      const j = first + Math.floor((now - start) / 1000 / exact + 1e-9);
      if (j >= this.frameCount() - 1) {
        this.showFrame(this.frameCount() - 1);
        this.playing = false;
        this.container.dataset.playing = 'false';
        return;
      }
      if (j !== this.frame) this.showFrame(j);
      requestAnimationFrame(tick);
    };
    this.container.dataset.playing = 'true';
    requestAnimationFrame(tick);
  }

  pause() {
    this.playing = false;
    this.container.dataset.playing = 'false';
  }

  render() {
    if (!this.renderer) return;
    this.renderer.render(this.scene, this.camera);
  }
}
