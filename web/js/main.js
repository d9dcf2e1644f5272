// tempokey studio: wires the views to the server. Every number the page shows about a retime or a
// reduction is the server's (PlanRetime, jobs' reports); the page edits knots and settings,
// sends them, and draws the answers.
import * as api from './api.js';
import {VelocityEditor} from './velocity_editor.js';
import {TimeMapView} from './time_map_view.js';
import {Preview} from './preview.js';
import {CurveView} from './curve_view.js';

const $ = (id) => document.getElementById(id);
const RETIME_DELAY_MS = 350;
const REDUCE_DELAY_MS = 350;

const state = {
  info: null,
  clip: null,           // {id, header, name, fileName, frameTime, frameCount, duration}
  samples: null,        // source channels (Float64Array each)
  plan: null,
  planSeq: 0,
  lastEdit: 0,
  holds: [],            // [{at, duration}] seconds
  retimeJob: null,      // {jobId, speedText}
  reduced: null,        // {jobId, curves, report, settings}
};

// ---- messages ------------------------------------------------------------------------------
function showMessage(text, kind = 'error') {
  const box = $('message');
  box.textContent = text;
  box.className = kind;
  box.hidden = !text;
}

function describe(error) {
  return error instanceof api.ApiError ? `${error.status}: ${error.message}` : String(error.message || error);
}

async function guarded(what, work) {
  try {
    return await work();
  } catch (error) {
    if (error instanceof api.ApiError && error.status === 'UNAUTHENTICATED') {
      $('token-box').hidden = false;
      showMessage(`${what}: the server wants a bearer token (enter it above): ${error.message}`);
    } else {
      showMessage(`${what}: ${describe(error)}`);
    }
    return undefined;
  }
}

// ---- views ---------------------------------------------------------------------------------
const editor = new VelocityEditor($('editor'), {
  onChange: () => {
    state.lastEdit = performance.now();
    requestPlan();
  },
  onSelect: () => showSelectedKnot(),
});
const timeMap = new TimeMapView($('time-map'));
const preview = new Preview($('preview'), {onFrame: (j, tau) => showFrame(j, tau)});
const curves = new CurveView($('curves'));

// ---- the clip ------------------------------------------------------------------------------
function readBase64(file) {
  return new Promise((resolve, reject) => {
    const reader = new FileReader();
    reader.onload = () => resolve(String(reader.result).replace(/^data:[^,]*,/, ''));
    reader.onerror = () => reject(reader.error);
    reader.readAsDataURL(file);
  });
}

async function openFile(file) {
  showMessage('');
  $('clip-info').dataset.state = 'loading';
  const content = await readBase64(file);
  const request = {fileName: file.name, content};
  if (/\.csv$/i.test(file.name)) request.csvFrameTimeSeconds = 1 / Number($('csv-fps').value || 30);
  // The server's message names the file, line and column already ("walk.bvh:12:7: ...").
  let parsed;
  try {
    parsed = await api.call('ParseClipFile', request);
  } catch (error) {
    if (error instanceof api.ApiError && error.status === 'UNAUTHENTICATED') {
      $('token-box').hidden = false;
    }
    showMessage(error instanceof api.ApiError && error.status === 'INVALID_ARGUMENT' ? error.message : describe(error));
  }
  if (!parsed) {
    $('clip-info').dataset.state = state.clip ? 'loaded' : 'empty';
    return;
  }
  const header = parsed.header;
  const clip = {
    id: parsed.clipId, header, name: header.name, fileName: file.name,
    frameTime: header.frameTimeSeconds, frameCount: Number(header.frameCount),
  };
  clip.duration = (clip.frameCount - 1) * clip.frameTime;
  const samples = await guarded('reading the clip back', () => api.fetchResult('GetClip', {clipId: clip.id}));
  if (!samples) return;
  state.clip = clip;
  state.samples = samples.channels;
  state.holds = [];
  state.plan = null;
  state.retimeJob = null;
  state.reduced = null;
  const fps = 1 / clip.frameTime;
  $('clip-info').textContent = `${file.name}: ${clip.frameCount} frames at ${+fps.toFixed(3)} fps, ` +
      `${clip.duration.toFixed(3)} s, ${header.joints.length} joints, ${header.channels.length} channels`;
  $('clip-info').dataset.state = 'loaded';
  $('clip-info').dataset.clipId = clip.id;
  $('domain').value = 'source';
  editor.setTimeline(clip.duration, clip.frameTime);
  editor.setKnots([{t: 0, unit: 's', v: 1}]);
  renderHolds();
  fillChannels();
  const bvh = await guarded('the source skeleton', () => api.exportFile({clipId: clip.id}, 'bvh'));
  if (bvh && header.joints.length > 0) preview.setSource(new TextDecoder().decode(bvh.bytes));
  showSelectedKnot();
  requestPlan();
  scheduleReduce(0);
}

// ---- retime settings -------------------------------------------------------------------------
function domain() {
  return $('domain').value;
}

function retimeOperation() {
  const knots = editor.knots.map((k) => ({time: k.unit === 'f' ? {frames: k.t} : {seconds: k.t}, speed: k.v}));
  const op = {};
  op[domain() === 'source' ? 'speedOverSource' : 'speedOverOutput'] = knots;
  op.holds = state.holds.map((h) => ({at: {seconds: h.at}, durationSeconds: h.duration}));
  op.reverse = $('reverse').checked;
  op.disableFitToGrid = !$('fit-to-grid').checked;
  const fitFrames = $('fit-frames').value;
  if (fitFrames) op.fitFrames = Number(fitFrames);
  const fps = $('fps').value;
  if (fps) {
    const [n, d] = fps.split('/');
    op.outputRateNumerator = Number(n);
    op.outputRateDenominator = Number(d);
  }
  op.filter = 'RESAMPLE_FILTER_' + $('filter').value.toUpperCase();
  op.method = 'RETIME_METHOD_' + $('retime-method').value.toUpperCase();
  op.minSpeed = Number($('min-speed').value) || 0;
  op.maxSpeed = Number($('max-speed').value) || 0;
  return op;
}

// The same settings as `tempokey retime` flags (README "Speed curves"); the --speed text is the
// server's own writing of the knots (ParseSpeedKnots reads it back to the same knots).
function retimeCommand(speedText) {
  const c = state.clip;
  const stem = c.fileName.replace(/\.[^.]*$/, '');
  const flags = [`tempokey retime ${c.fileName} -o ${stem}-retimed.bvh`, `--speed "${speedText}"`];
  if (domain() === 'output') flags.push('--speed-over output');
  for (const h of state.holds) flags.push(`--hold ${h.at}s:${h.duration}`);
  if ($('fps').value) {
    const [n, d] = $('fps').value.split('/');
    flags.push(`--fps ${d === '1' ? n : n + '/' + d}`);
  }
  if (!$('fit-to-grid').checked) flags.push('--no-fit-to-grid');
  if ($('fit-frames').value) flags.push(`--fit-frames ${Number($('fit-frames').value)}`);
  if ($('reverse').checked) flags.push('--reverse');
  if ($('filter').value !== 'tent') flags.push(`--filter ${$('filter').value}`);
  if ($('retime-method').value !== 'exact') flags.push(`--method ${$('retime-method').value}`);
  if (Number($('min-speed').value) !== 0.01) flags.push(`--min-speed ${Number($('min-speed').value)}`);
  if (Number($('max-speed').value) !== 100) flags.push(`--max-speed ${Number($('max-speed').value)}`);
  return flags.join(' ');
}

function settingsChanged() {
  state.lastEdit = performance.now();
  editor.setLimits(Number($('min-speed').value) || 0.01, Number($('max-speed').value) || 100);
  requestPlan();
}

// ---- live plan (PlanRetime): the latest edit wins, one request in flight -------------------------
let planInFlight = false;
let planWanted = false;

function requestPlan() {
  if (!state.clip) return;
  planWanted = true;
  if (!planInFlight) runPlan();
}

async function runPlan() {
  planInFlight = true;
  document.body.dataset.planPending = 'true';
  while (planWanted) {
    planWanted = false;
    const editTime = state.lastEdit;
    const op = retimeOperation();
    try {
      const plan = await api.call('PlanRetime', {clipId: state.clip.id, retime: op, maxPoints: 100000});
      applyPlan(plan, op, editTime);
      $('retime').querySelector('#speed-text').classList.remove('invalid');
      if ($('message').textContent.startsWith('retime:')) showMessage('');
    } catch (error) {
      showMessage(`retime: ${describe(error)}`);
      $('retime-status').dataset.state = 'invalid';
    }
  }
  planInFlight = false;
  document.body.dataset.planPending = 'false';
}

function applyPlan(plan, op, editTime) {
  state.plan = plan;
  state.plan.op = op;
  const r = plan.report;
  const seconds = r.outputDurationSeconds;
  $('duration').textContent = `${seconds.toFixed(6)} s`;
  $('duration').dataset.seconds = String(seconds);
  $('frame-count').textContent = String(r.outputFrameCount);
  $('fit-factor').textContent = r.fitFactor.toFixed(6);
  $('max-ratio').textContent = r.maxDecimationRatio.toFixed(3);
  $('filtered').textContent = String(r.filteredSampleCount);
  if (document.activeElement !== $('speed-text')) $('speed-text').value = plan.speedText;
  $('speed-text-error').hidden = true;
  $('retime-command').textContent = retimeCommand(plan.speedText);
  const knotPoints = domain() === 'source'
    ? editor.knots.map((k, i) => ({source: editor.seconds(k), output: plan.knotOutputTimeSeconds[i]}))
    : editor.knots.map((k, i) => ({source: plan.knotSourceTimeSeconds[i], output: editor.seconds(k)}))
        .filter((p) => p.source !== undefined);
  timeMap.setPlan(plan, knotPoints.filter((p) => p.output !== undefined));
  if (domain() === 'output') {
    editor.setTimeline(Math.max(seconds, ...editor.knots.map((k) => editor.seconds(k))), plan.outputFrameTimeSeconds);
  }
  state.planSeq += 1;
  const body = document.body.dataset;
  body.planSeq = String(state.planSeq);
  body.planLatencyMs = String(performance.now() - editTime);
  scheduleRetime();
}

// ---- the retimed result (a stored job, for the preview and the downloads) -----------------------
let retimeTimer = 0;
let retimeRun = 0;

function scheduleRetime() {
  clearTimeout(retimeTimer);
  $('retime-status').dataset.state = 'pending';
  $('retime-status').textContent = 'retiming soon…';
  retimeTimer = setTimeout(runRetime, RETIME_DELAY_MS);
}

async function runRetime() {
  const run = ++retimeRun;
  const clip = state.clip;
  const op = retimeOperation();
  const speedText = state.plan ? state.plan.speedText : '';
  const command = state.plan ? retimeCommand(speedText) : '';
  $('retime-status').dataset.state = 'running';
  $('retime-status').textContent = 'retiming on the server…';
  const done = await guarded('retime', async () => {
    const job = await api.call('SubmitJob', {clipId: clip.id, operations: [{retime: op}], labels: {source: 'studio'}});
    await api.waitForJob(job.jobId);
    const [file, plan] = await Promise.all([
      api.exportFile({jobId: job.jobId}, 'bvh'),
      api.call('PlanRetime', {clipId: clip.id, retime: op, maxPoints: 100000}),
    ]);
    return {job, file, plan};
  });
  if (run !== retimeRun || clip !== state.clip) return;  // superseded by a newer edit
  if (!done) {
    $('retime-status').dataset.state = 'failed';
    return;
  }
  const previous = state.retimeJob;
  state.retimeJob = {jobId: done.job.jobId, speedText};
  if (previous) api.call('DeleteJob', {jobId: previous.jobId}).catch(() => {});
  preview.setResult(new TextDecoder().decode(done.file.bytes), done.plan);
  $('scrub').max = String(preview.frameCount() - 1);
  const status = $('retime-status');
  status.textContent = `result: ${done.plan.report.outputFrameCount} frames, job ${done.job.jobId}`;
  status.dataset.jobId = done.job.jobId;
  status.dataset.speedText = speedText;
  status.dataset.command = command;
  status.dataset.state = 'done';
  renderDownloads('downloads-retime', false);
}

// ---- knots, text, holds -----------------------------------------------------------------------
function showSelectedKnot() {
  const k = editor.selectedKnot();
  if (!k) return;
  $('knot-time').value = String(k.t);
  $('knot-unit').textContent = k.unit;
  $('knot-speed').value = String(k.v);
}

function applyKnotFields() {
  if ($('knot-time').value.trim() === '' || $('knot-speed').value.trim() === '') return;
  const time = Number($('knot-time').value);
  const speed = Number($('knot-speed').value);
  if (!Number.isFinite(time) || !Number.isFinite(speed) || speed <= 0) return;
  editor.setSelected(time, speed);
}

async function applySpeedText() {
  const text = $('speed-text').value;
  // Enter and the blur after it both fire: apply a text once, and never over newer knots.
  if (state.plan && text === state.plan.speedText) return;
  try {
    const parsed = await api.call('ParseSpeedKnots', {text});
    const knots = parsed.knots.map((k) => ('frames' in k.time
      ? {t: k.time.frames, unit: 'f', v: k.speed}
      : {t: k.time.seconds, unit: 's', v: k.speed}));
    $('speed-text-error').hidden = true;
    editor.setKnots(knots, Math.min(editor.selected, knots.length - 1));
    state.lastEdit = performance.now();
    showSelectedKnot();
    requestPlan();
  } catch (error) {
    $('speed-text-error').textContent = describe(error);
    $('speed-text-error').hidden = false;
  }
}

// Source <-> output time: knots keep their speeds and move to where the server's map puts them.
function switchDomain() {
  const plan = state.plan;
  const toOutput = domain() === 'output';
  const times = plan ? (toOutput ? plan.knotOutputTimeSeconds : plan.knotSourceTimeSeconds) : [];
  const knots = editor.knots.map((k, i) => ({
    t: times[i] !== undefined ? Math.round(times[i] * 1000) / 1000 : editor.seconds(k), unit: 's', v: k.v}));
  if (toOutput) {
    editor.setTimeline(plan ? plan.report.outputDurationSeconds : state.clip.duration,
        plan ? plan.outputFrameTimeSeconds : state.clip.frameTime);
  } else {
    editor.setTimeline(state.clip.duration, state.clip.frameTime);
  }
  editor.setHolds(toOutput ? [] : state.holds.map((h) => ({atSeconds: h.at, duration: h.duration})));
  editor.setKnots(knots, editor.selected);
  state.lastEdit = performance.now();
  requestPlan();
}

function renderHolds() {
  const list = $('holds');
  list.textContent = '';
  state.holds.forEach((h, i) => {
    const item = document.createElement('span');
    item.textContent = `${h.at}s:${h.duration}`;
    const remove = document.createElement('button');
    remove.textContent = '×';
    remove.title = 'remove this hold';
    remove.addEventListener('click', () => {
      state.holds.splice(i, 1);
      renderHolds();
      settingsChanged();
    });
    item.appendChild(remove);
    list.appendChild(item);
  });
  editor.setHolds(domain() === 'source' ? state.holds.map((h) => ({atSeconds: h.at, duration: h.duration})) : []);
}

// ---- preview transport ---------------------------------------------------------------------------
function showFrame(j, tau) {
  const plan = preview.plan || state.plan;
  const outFrame = plan ? plan.outputFrameTimeSeconds : state.clip ? state.clip.frameTime : 0;
  const t = j * outFrame;
  $('scrub').value = String(j);
  const srcFrame = state.clip ? tau / state.clip.frameTime : 0;
  $('frame-readout').textContent =
      `output frame ${j} / ${preview.frameCount() - 1} · t = ${t.toFixed(4)} s · source τ = ${tau.toFixed(4)} s (frame ${srcFrame.toFixed(2)})`;
  timeMap.setCursor({source: tau, output: t});
}

function togglePlay() {
  if (preview.playing) {
    preview.pause();
    $('play').textContent = 'play';
  } else {
    preview.play();
    $('play').textContent = 'pause';
  }
}

// ---- reduction --------------------------------------------------------------------------------
// The joint list (plus "plain channels" when the clip has some) and the channels of the joint
// picked; the two selects together pick one channel.
function channelsOfJoint(joint) {
  const channels = [];
  state.clip.header.channels.forEach((c, i) => {
    const owner = c.jointIndex === undefined || c.jointIndex === null ? -1 : c.jointIndex;
    if (owner === joint) channels.push(i);
  });
  return channels;
}

function fillChannelsOf(joint, selected = null) {
  const select = $('channel');
  select.textContent = '';
  for (const i of channelsOfJoint(joint)) {
    const option = document.createElement('option');
    option.value = String(i);
    const name = api.channelName(state.clip.header, i);
    option.textContent = joint >= 0 ? name.slice(name.lastIndexOf('.') + 1) : name;
    select.appendChild(option);
  }
  if (selected !== null) select.value = String(selected);
}

function fillChannels() {
  const header = state.clip.header;
  const joints = $('joint');
  joints.textContent = '';
  header.joints.forEach((j, i) => {
    if (!channelsOfJoint(i).length) return;
    const option = document.createElement('option');
    option.value = String(i);
    option.textContent = j.name;
    joints.appendChild(option);
  });
  if (channelsOfJoint(-1).length) {
    const option = document.createElement('option');
    option.value = '-1';
    option.textContent = '(plain channels)';
    joints.appendChild(option);
  }
  // First view: the rotation that moves most without jumping (no Euler flips), where keys and
  // handles have something to show.
  let preferred = 0;
  let widest = -1;
  state.samples.forEach((samples, i) => {
    if (!api.isRotation(header, i)) return;
    let lo = Infinity;
    let hi = -Infinity;
    let jump = 0;
    samples.forEach((v, f) => {
      lo = Math.min(lo, v);
      hi = Math.max(hi, v);
      if (f > 0) jump = Math.max(jump, Math.abs(v - samples[f - 1]));
    });
    if (jump < 15 && hi - lo > widest) {
      widest = hi - lo;
      preferred = i;
    }
  });
  const owner = header.channels[preferred].jointIndex;
  joints.value = String(owner === undefined || owner === null ? -1 : owner);
  fillChannelsOf(Number(joints.value), preferred);
}

// The reduce operation the settings ask for. An empty position bound is left unset: the server's
// default, 0.3 % of the figure's height (the CLI's too).
function reduceOperation() {
  const method = $('reduce-method').value;
  if (method === 'paper') return {method: 'REDUCE_METHOD_PAPER', paper: {}};
  if (method === 'noise') return {method: 'REDUCE_METHOD_NOISE', noise: {}};
  if (method === 'joint') {
    return {method: 'REDUCE_METHOD_TOLERANCE',
      tolerance: {maxJointErrorPercentOfHeight: Number($('joint-tolerance').value)}};
  }
  const tolerance = {maxRotationErrorDegrees: Number($('tolerance').value)};
  if ($('position-tolerance').value.trim() !== '') tolerance.maxPositionError = Number($('position-tolerance').value);
  return {method: 'REDUCE_METHOD_TOLERANCE', tolerance};
}

// The same reduction as a CLI command (its flags are the CLI's own).
function reduceCommand() {
  const c = state.clip;
  const stem = c.fileName.replace(/\.[^.]*$/, '');
  const flags = [`tempokey reduce ${c.fileName} -o ${stem}-keys.anim`];
  const method = $('reduce-method').value;
  if (method === 'paper' || method === 'noise') {
    flags.push(`--method ${method}`);
  } else if (method === 'joint') {
    flags.push(`--joint-tolerance ${Number($('joint-tolerance').value)}%`);
  } else {
    flags.push(`--tolerance ${Number($('tolerance').value)}`);
    if ($('position-tolerance').value.trim() !== '') {
      flags.push(`--position-tolerance ${Number($('position-tolerance').value)}`);
    }
  }
  return flags.join(' ');
}

// Shows the inputs of the chosen method only.
function showReduceInputs() {
  const method = $('reduce-method').value;
  document.querySelectorAll('.tolerance-only').forEach((e) => (e.hidden = method !== 'tolerance'));
  document.querySelectorAll('.joint-only').forEach((e) => (e.hidden = method !== 'joint'));
}

let reduceTimer = 0;
let reduceRun = 0;

function scheduleReduce(delay = REDUCE_DELAY_MS) {
  clearTimeout(reduceTimer);
  if (!state.clip) return;
  const method = $('reduce-method').value;
  if (method === 'tolerance' && $('tolerance').value.trim() === '') return;
  if (method === 'joint' && $('joint-tolerance').value.trim() === '') return;
  $('reduce-status').dataset.state = 'pending';
  reduceTimer = setTimeout(runReduce, delay);
}

async function runReduce() {
  const run = ++reduceRun;
  const clip = state.clip;
  const op = reduceOperation();
  const command = reduceCommand();
  showReduceInputs();
  $('reduce-status').dataset.state = 'running';
  $('reduce-status').textContent = 'reducing on the server…';
  const done = await guarded('reduce', async () => {
    const job = await api.call('SubmitJob', {clipId: clip.id, operations: [{reduce: op}], labels: {source: 'studio'}});
    await api.waitForJob(job.jobId);
    const result = await api.fetchResult('GetJobResult', {jobId: job.jobId});
    return {job, result};
  });
  if (run !== reduceRun || clip !== state.clip) return;
  if (!done) {
    $('reduce-status').dataset.state = 'failed';
    return;
  }
  const previous = state.reduced;
  const report = done.result.reports.find((r) => r.reduction)?.reduction || {};
  state.reduced = {jobId: done.job.jobId, curves: done.result.curves, report, op};
  if (previous) api.call('DeleteJob', {jobId: previous.jobId}).catch(() => {});
  $('key-count').textContent = String(report.keyCount);
  $('reduce-command').textContent = command;
  const status = $('reduce-status');
  status.textContent = `${report.keyCount} keys for ${report.sampleCount} samples, job ${done.job.jobId}`;
  status.dataset.jobId = done.job.jobId;
  status.dataset.command = command;
  status.dataset.state = 'done';
  showChannel();
  renderDownloads('downloads-reduce', true);
}

// The report as the server sent it: every field of the whole-clip report (whatever this server's
// reductions carry, world-space error included when they have it), then the channel's own.
function renderReport(channel) {
  const body = $('reduce-report').tBodies[0];
  body.textContent = '';
  const row = (name, value, head = false) => {
    const tr = body.insertRow();
    if (head) tr.className = 'head';
    tr.insertCell().textContent = name;
    tr.insertCell().textContent = value;
  };
  const show = (value) => (typeof value === 'number' && !Number.isInteger(value) ? value.toPrecision(6) : String(value));
  const report = state.reduced.report;
  row('whole clip', '', true);
  for (const [name, value] of Object.entries(report)) {
    if (name === 'channels' || typeof value === 'object') continue;
    let text = show(value);
    if (name === 'worstChannelIndex') text += ` (${api.channelName(state.clip.header, Number(value))})`;
    row(name, text);
  }
  if (report.worldError) {
    // Where the audience sees it: every joint and end site through the skeleton, in file units.
    row('joints (world space)', '', true);
    for (const [name, value] of Object.entries(report.worldError)) row(name, show(value));
  }
  const own = (report.channels || []).find((c) => Number(c.channelIndex) === channel);
  if (own) {
    row(api.channelName(state.clip.header, channel), '', true);
    for (const [name, value] of Object.entries(own)) if (name !== 'channelIndex') row(name, show(value));
  }
}

function showChannel() {
  if (!state.clip || !state.samples) return;
  const channel = Number($('channel').value);
  const rotation = api.isRotation(state.clip.header, channel);
  const reduced = state.reduced;
  let curve = null;
  let bound = null;
  let worst = null;
  if (reduced) {
    curve = reduced.curves[channel];
    const own = (reduced.report.channels || []).find((c) => Number(c.channelIndex) === channel);
    const tolerance = reduced.op.tolerance;
    const perChannel = tolerance && (rotation ? tolerance.maxRotationErrorDegrees : tolerance.maxPositionError);
    if (perChannel !== undefined && perChannel !== null) {
      bound = perChannel;
    } else if (own) {
      bound = own.maxError;
    }
    if (own) worst = Number(own.maxErrorFrame);
    renderReport(channel);
  }
  curves.set({samples: state.samples[channel], frameTime: state.clip.frameTime, rotation, curve, bound,
    worstFrame: worst, unit: rotation ? '°' : ''});
}

// ---- downloads ------------------------------------------------------------------------------------
function renderDownloads(id, keyed) {
  const row = $(id);
  row.querySelectorAll('button').forEach((b) => b.remove());
  for (const format of state.info.exportFormats) {
    if (!keyed && format.keyed) continue;
    const button = document.createElement('button');
    button.id = `download-${keyed ? 'reduce' : 'retime'}-${format.name}`;
    button.textContent = format.extension;
    const gltf = format.mediaType.startsWith('model/gltf');
    button.title = keyed && !format.keyed && !gltf ? 'the curves baked at the source rate' : format.mediaType;
    button.addEventListener('click', () => download(keyed, format));
    row.appendChild(button);
  }
}

async function download(keyed, format) {
  const job = keyed ? state.reduced : state.retimeJob;
  if (!job) return;
  const file = await guarded('download', () => api.exportFile({jobId: job.jobId}, format.name));
  if (!file) return;
  const stem = state.clip.fileName.replace(/\.[^.]*$/, '');
  const link = document.createElement('a');
  link.href = URL.createObjectURL(new Blob([file.bytes], {type: file.mediaType}));
  link.download = `${stem}-${keyed ? 'keys' : 'retimed'}${format.extension}`;
  document.body.appendChild(link);
  link.click();
  link.remove();
  setTimeout(() => URL.revokeObjectURL(link.href), 60000);
}

// ---- events -------------------------------------------------------------------------------------
$('file-input').addEventListener('change', (e) => {
  if (e.target.files.length) openFile(e.target.files[0]).finally(() => (e.target.value = ''));
});
let dragDepth = 0;
window.addEventListener('dragenter', (e) => {
  e.preventDefault();
  dragDepth += 1;
  $('drop').hidden = false;
});
window.addEventListener('dragleave', () => {
  dragDepth = Math.max(0, dragDepth - 1);
  if (!dragDepth) $('drop').hidden = true;
});
window.addEventListener('dragover', (e) => e.preventDefault());
window.addEventListener('drop', (e) => {
  e.preventDefault();
  dragDepth = 0;
  $('drop').hidden = true;
  if (e.dataTransfer.files.length) openFile(e.dataTransfer.files[0]);
});
$('knot-time').addEventListener('change', applyKnotFields);
$('knot-speed').addEventListener('change', applyKnotFields);
$('knot-delete').addEventListener('click', () => editor.keyDown(new KeyboardEvent('keydown', {key: 'Delete'})));
$('knot-step').addEventListener('click', () => editor.keyDown(new KeyboardEvent('keydown', {key: 's'})));
$('speed-text').addEventListener('change', applySpeedText);
$('speed-text').addEventListener('keydown', (e) => {
  if (e.key === 'Enter') {
    e.preventDefault();
    applySpeedText();
  }
});
$('domain').addEventListener('change', switchDomain);
for (const id of ['min-speed', 'max-speed', 'fps', 'fit-to-grid', 'fit-frames', 'reverse', 'filter', 'retime-method']) {
  $(id).addEventListener('change', settingsChanged);
}
$('add-hold').addEventListener('click', () => {
  const at = Number($('hold-at').value);
  const duration = Number($('hold-duration').value);
  if (!Number.isFinite(at) || !(duration > 0)) return;
  state.holds.push({at, duration});
  state.holds.sort((a, b) => a.at - b.at);
  renderHolds();
  settingsChanged();
});
$('play').addEventListener('click', togglePlay);
$('step-back').addEventListener('click', () => preview.step(-1));
$('step-forward').addEventListener('click', () => preview.step(1));
$('scrub').addEventListener('input', (e) => {
  preview.pause();
  $('play').textContent = 'play';
  preview.showFrame(Number(e.target.value));
});
$('preview').addEventListener('keydown', (e) => {
  if (e.key === ' ') togglePlay();
  else if (e.key === 'ArrowLeft') preview.step(-1);
  else if (e.key === 'ArrowRight') preview.step(1);
  else return;
  e.preventDefault();
});
new MutationObserver(() => {
  if ($('preview').dataset.playing === 'false') $('play').textContent = 'play';
}).observe($('preview'), {attributes: true, attributeFilter: ['data-playing']});
$('channel').addEventListener('change', showChannel);
$('joint').addEventListener('change', () => {
  fillChannelsOf(Number($('joint').value));
  showChannel();
});
for (const id of ['reduce-method', 'tolerance', 'position-tolerance', 'joint-tolerance']) $(id).addEventListener('change', () => scheduleReduce());
$('reduce-method').addEventListener('change', showReduceInputs);
$('run-reduce').addEventListener('click', () => scheduleReduce(0));
$('token').addEventListener('change', (e) => {
  api.setToken(e.target.value.trim());
  showMessage('token set', 'info');
  start();
});

async function start() {
  const info = await guarded('connecting', () => api.call('GetServerInfo'));
  if (!info) return;
  state.info = info;
  document.body.dataset.ready = 'true';
  if ($('message').className === 'info') showMessage('');
}

start();
