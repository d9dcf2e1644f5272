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
  plan: null,           // the latest plan the server accepted, with its op
  planRefused: false,   // the settings since that plan are refused (by the server or the page)
  planSeq: 0,
  lastEdit: 0,
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

// Shows what went wrong with `what`; a call the page stopped itself (a newer edit, leaving the
// page) is nobody's error and shows nothing.
function reportError(what, error) {
  if (api.isStopped(error)) return;
  if (error instanceof api.ApiError && error.status === 'UNAUTHENTICATED') {
    $('token-box').hidden = false;
    showMessage(`${what}: the server wants a bearer token (enter it above): ${error.message}`);
  } else {
    showMessage(`${what}: ${describe(error)}`);
  }
}

async function guarded(what, work) {
  try {
    return await work();
  } catch (error) {
    reportError(what, error);
    return undefined;
  }
}

// Clears the banner if it still shows a message of `what` (the prefix reportError gives it).
function clearMessageOf(what) {
  if ($('message').textContent.startsWith(what + ':')) showMessage('');
}

// A word for a POSIX shell: as it is when it has nothing the shell reads, else in single quotes
// (a ' inside written '\''), so a pasted command line never runs a file's name. A word starting
// with '=' is quoted too (zsh reads =cmd as the path of cmd).
function shellWord(word) {
  const text = String(word);
  return /^[A-Za-z0-9_.,:\/%+=@-]+$/.test(text) && !text.startsWith('=') ? text : `'${text.replace(/'/g, "'\\''")}'`;
}

// A file's name as a command's argument: a relative name starting with '-' gets './' before it,
// or the command would read it as a flag (`tempokey retime -walk.bvh` is no file).
function fileArgument(name) {
  return name.startsWith('-') ? './' + name : name;
}

function commandLine(words) {
  return words.map(shellWord).join(' ');
}

// ---- views ---------------------------------------------------------------------------------
const editor = new VelocityEditor($('editor'), {
  onChange: () => {
    state.lastEdit = performance.now();
    // The speed function moved on: an error about text typed, or hold fields filled, before
    // it no longer applies.
    if (!$('speed-text-error').hidden) showSpeedTextError('');
    showHoldError('');
    renderHolds();  // an undo or a redo may have changed them
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

// The largest file ParseClipFile takes: its request is JSON of at most the server's message limit
// (GetServerInfo), the file's bytes in it as base64 (4 characters per 3 bytes), less room for the
// rest of the request.
function maxFileBytes() {
  const message = Number(state.info && state.info.maxMessageBytes) || 64 * 1024 * 1024;
  return Math.floor((message - 64 * 1024) / 4) * 3;
}

function megabytes(bytes) {
  return `${+(bytes / (1024 * 1024)).toFixed(1)} MiB`;
}

// Formats the server can write for this clip: BVH and glTF need a skeleton (the server refuses
// them for plain channels, "cannot write BVH: the clip has no skeleton").
const SKELETON_FORMATS = new Set(['bvh', 'gltf', 'glb']);

function hasSkeleton(clip) {
  return clip.header.joints.length > 0;
}

let openSeq = 0;

async function openFile(file) {
  const open = ++openSeq;
  showMessage('');
  if (file.size > maxFileBytes()) {
    // Without the server's info (it could not be asked yet: a token first), its default limit.
    const limit = state.info && state.info.maxMessageBytes
      ? `its limit of ${state.info.maxMessageBytes} bytes per request`
      : "the default limit of 64 MiB per request (the server's own is not known yet)";
    showMessage(`${file.name} is ${megabytes(file.size)}: the server takes files up to ` +
        `${megabytes(maxFileBytes())} (${limit}, the file travelling as base64)`);
    return;
  }
  $('clip-info').dataset.state = 'loading';
  $('open-status').textContent = `reading ${file.name} (${megabytes(file.size)})…`;
  try {
    const clip = await loadClip(file);
    if (clip && open === openSeq) showClip(clip);
  } catch (error) {
    // The file could not be read (FileReader), or the page failed to show what the server sent.
    if (open === openSeq) reportError(`opening ${file.name}`, error);
  } finally {
    if (open === openSeq) {
      $('open-status').textContent = '';
      $('clip-info').dataset.state = state.clip ? 'loaded' : 'empty';
    }
  }
}

// The file parsed and read back by the server: {clip, samples}, or undefined with the message shown.
async function loadClip(file) {
  const content = await readBase64(file);
  $('open-status').textContent = `sending ${file.name} to the server…`;
  const request = {fileName: file.name, content};
  const csvFps = Number($('csv-fps').value || 30);
  if (/\.csv$/i.test(file.name)) request.csvFrameTimeSeconds = 1 / csvFps;
  // The server's message names the file, line and column already ("walk.bvh:12:7: ...").
  let parsed;
  try {
    parsed = await api.call('ParseClipFile', request);
  } catch (error) {
    if (error instanceof api.ApiError && error.status === 'UNAUTHENTICATED') {
      $('token-box').hidden = false;
    }
    if (!api.isStopped(error)) {
      showMessage(error instanceof api.ApiError && error.status === 'INVALID_ARGUMENT' ? error.message : describe(error));
    }
    return undefined;
  }
  const header = parsed.header;
  const clip = {
    id: parsed.clipId, header, name: header.name, fileName: file.name,
    frameTime: header.frameTimeSeconds, frameCount: Number(header.frameCount),
    csvFps: request.csvFrameTimeSeconds ? csvFps : null,
  };
  clip.duration = (clip.frameCount - 1) * clip.frameTime;
  const samples = await guarded('reading the clip back', () => api.fetchResult('GetClip', {clipId: clip.id}));
  if (!samples) return undefined;
  return {clip, samples};
}

// A new clip replaces the old one and everything made from it: its runs are stopped, its jobs
// deleted, its preview, results, downloads and commands cleared.
function showClip({clip, samples}) {
  forgetResults();
  state.clip = clip;
  state.samples = samples.channels;
  state.plan = null;
  const header = clip.header;
  const fps = 1 / clip.frameTime;
  $('clip-info').textContent = `${clip.fileName}: ${clip.frameCount} frames at ${+fps.toFixed(3)} fps, ` +
      `${clip.duration.toFixed(3)} s, ${header.joints.length} joints, ${header.channels.length} channels`;
  $('clip-info').dataset.state = 'loaded';
  $('clip-info').dataset.clipId = clip.id;
  $('domain').value = 'source';
  editor.setTimeline(clip.duration, clip.frameTime);
  editor.setKnots([{t: 0, unit: 's', v: 1}]);
  editor.setHolds([]);
  editor.showHolds(true);
  editor.forgetHistory();
  showHoldError('');
  renderHolds();
  fillChannels();
  showChannel();
  showSelectedKnot();
  state.previewSource = loadPreviewSource(clip);
  requestPlan();
  scheduleReduce(0);
}

// The source skeleton in the preview (BVH as the server writes it); a clip of plain channels
// has none to show. Not awaited by the rest: the server may be busy with other work.
async function loadPreviewSource(clip) {
  $('preview-note').hidden = hasSkeleton(clip);
  if (!hasSkeleton(clip)) return;
  await guarded('the source skeleton', async () => {
    const bvh = await api.exportFile({clipId: clip.id}, 'bvh');
    if (clip === state.clip) preview.setSource(new TextDecoder().decode(bvh.bytes));
  });
}

// Stops the runs of the clip open so far and gives its jobs back to the server.
function forgetResults() {
  retimeRuns.stop();
  reduceRuns.stop();
  for (const kept of [state.retimeJob, state.reduced]) if (kept) api.releaseJob(kept.jobId);
  state.retimeJob = null;
  state.reduced = null;
  preview.clear();
  $('scrub').max = '0';
  $('frame-readout').textContent = '–';
  for (const id of ['downloads-retime', 'downloads-reduce']) $(id).querySelectorAll('button').forEach((b) => b.remove());
  for (const id of ['retime-command', 'reduce-command']) $(id).textContent = '';
  for (const kind of ['retime', 'reduce']) showStatus(kind, 'idle', '');
  $('key-count').textContent = '–';
  $('reduce-report').tBodies[0].textContent = '';
}

// ---- retime settings -------------------------------------------------------------------------
function domain() {
  return $('domain').value;
}

function retimeOperation() {
  const knots = editor.knots.map((k) => ({time: k.unit === 'f' ? {frames: k.t} : {seconds: k.t}, speed: k.v}));
  const op = {};
  op[domain() === 'source' ? 'speedOverSource' : 'speedOverOutput'] = knots;
  op.holds = editor.holds.map((h) => ({at: {seconds: h.atSeconds}, durationSeconds: h.duration}));
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

// The file and output words of a command line: a CSV input needs its rate (CSV files do not
// store one), and a clip without a skeleton is written as CSV where the output would be BVH (BVH
// needs a skeleton; .anim does not, and .csv there would be the curves baked, not keys).
function fileWords(command, suffix, extension) {
  const c = state.clip;
  const stem = c.fileName.replace(/\.[^.]*$/, '');
  const output = stem + suffix + (extension === '.bvh' && !hasSkeleton(c) ? '.csv' : extension);
  const words = ['tempokey', command, fileArgument(c.fileName), '-o', fileArgument(output)];
  if (c.csvFps) words.push('--input-fps', c.csvFps);
  return words;
}

// The same settings as `tempokey retime` flags (README "Speed curves"); the --speed text is the
// server's own writing of the knots (ParseSpeedKnots reads it back to the same knots).
function retimeCommand(speedText) {
  const words = fileWords('retime', '-retimed', '.bvh');
  words.push('--speed', speedText);
  if (domain() === 'output') words.push('--speed-over', 'output');
  for (const h of editor.holds) words.push('--hold', `${h.atSeconds}s:${h.duration}`);
  if ($('fps').value) {
    const [n, d] = $('fps').value.split('/');
    words.push('--fps', d === '1' ? n : n + '/' + d);
  }
  if (!$('fit-to-grid').checked) words.push('--no-fit-to-grid');
  if ($('fit-frames').value) words.push('--fit-frames', Number($('fit-frames').value));
  if ($('reverse').checked) words.push('--reverse');
  if ($('filter').value !== 'tent') words.push('--filter', $('filter').value);
  if ($('retime-method').value !== 'exact') words.push('--method', $('retime-method').value);
  if (Number($('min-speed').value) !== 0.01) words.push('--min-speed', Number($('min-speed').value));
  if (Number($('max-speed').value) !== 100) words.push('--max-speed', Number($('max-speed').value));
  return commandLine(words);
}

// The speed limits the fields ask for ({min, max}), or {problem} for a range the server would
// refuse. An empty field is the server's default.
function speedLimits() {
  const field = (id, fallback) => ($(id).value.trim() === '' ? fallback : Number($(id).value));
  const min = field('min-speed', 0.01);
  const max = field('max-speed', 100);
  if (!(Number.isFinite(min) && min > 0) || !(Number.isFinite(max) && max > 0)) {
    return {problem: `the speed limits must be positive numbers, got ${$('min-speed').value || '–'} and ${$('max-speed').value || '–'}`};
  }
  if (min > max) return {problem: `the range [${min}, ${max}] is empty: the minimum is above the maximum`};
  return {min, max};
}

function settingsChanged() {
  state.lastEdit = performance.now();
  // Limits never touch the knots: they bound the editor's drags, and the server names any knot
  // beyond them; a range the server would refuse is refused here, the curve kept as it is.
  const limits = speedLimits();
  const invalid = !!limits.problem;
  $('min-speed').classList.toggle('invalid', invalid);
  $('max-speed').classList.toggle('invalid', invalid);
  if (invalid) {
    showMessage(`speed limits: ${limits.problem} (the knots are kept)`);
  } else {
    clearMessageOf('speed limits');
    editor.setLimits(limits.min, limits.max);
  }
  requestPlan();  // refused while the limits are
}

// ---- live plan (PlanRetime): the latest edit wins, one request in flight -------------------------
let planInFlight = false;
let planWanted = false;

function requestPlan() {
  if (!state.clip) return;
  // Limits the page refuses are not sent (a limit of 0 would reach the server, which reads 0
  // as its default): every edit while they stand is refused with them.
  if (speedLimits().problem) {
    refuseRetime('the speed limits are refused');
    return;
  }
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
      clearMessageOf('retime');
    } catch (error) {
      reportError('retime', error);
      if (!api.isStopped(error)) refuseRetime('the server refused the settings');
    }
  }
  planInFlight = false;
  document.body.dataset.planPending = 'false';
}

function applyPlan(plan, op, editTime) {
  state.plan = plan;
  state.plan.op = op;
  state.planRefused = false;
  const r = plan.report;
  const seconds = r.outputDurationSeconds;
  $('duration').textContent = `${seconds.toFixed(6)} s`;
  $('duration').dataset.seconds = String(seconds);
  $('frame-count').textContent = String(r.outputFrameCount);
  $('fit-factor').textContent = r.fitFactor.toFixed(6);
  $('max-ratio').textContent = r.maxDecimationRatio.toFixed(3);
  $('filtered').textContent = String(r.filteredSampleCount);
  if (document.activeElement !== $('speed-text') && speedTextReading === null) {
    // The text is the knots' own again: an error about text typed before is gone everywhere
    // (under the text, its red outline, the banner). Not while typed text is being read: its
    // answer applies it (or names its error) next, and the text is still the user's.
    $('speed-text').value = plan.speedText;
    showSpeedTextError('');
  }
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

// ---- runs: one job at a time of each kind ---------------------------------------------------
// The newest run of a kind (the retime, the reduction) supersedes the one before: its calls are
// stopped and its job, which nobody will look at, is cancelled and deleted. A run that succeeds
// keeps its job (the preview and the downloads read it) until the next success replaces it.
class Runs {
  constructor() {
    this.current = null;
  }
  start() {
    this.stop();
    this.current = {controller: new AbortController(), jobId: null};
    return this.current;
  }
  get signal() {
    return this.current.controller.signal;
  }
  isCurrent(run) {
    return this.current === run;
  }
  // Stops the current run; its job is released unless `keep` (it became the kept result).
  stop(keep = false) {
    const run = this.current;
    if (!run) return;
    this.current = null;
    run.controller.abort();
    if (run.jobId && !keep) api.releaseJob(run.jobId);
  }
}

const retimeRuns = new Runs();
const reduceRuns = new Runs();

// The status line of a kind, with its job's progress and Cancel button while one runs.
function showStatus(kind, stateName, text) {
  const status = $(`${kind}-status`);
  status.textContent = text;
  status.dataset.state = stateName;
  if (stateName !== 'done') {
    for (const name of ['jobId', 'command', 'speedText']) delete status.dataset[name];
  }
  if (stateName !== 'running') $(`${kind}-job`).hidden = true;
}

// A job snapshot's progress as the server reports it: its stage ("queued", "reduce 12/96") and
// fraction.
function showProgress(kind, job) {
  const row = $(`${kind}-job`);
  row.hidden = false;
  row.dataset.jobId = job.jobId;
  row.dataset.state = job.state;
  $(`${kind}-progress`).value = job.progress || 0;
  $(`${kind}-stage`).textContent = `${job.stage || job.state} · ${Math.round((job.progress || 0) * 100)} %`;
}

// Runs a job for `runs`: submits it, shows its progress until it ends, then `finish(job)`
// (fetching its result, with the run's signal). Resolves with {job, ...finish's answer}, or
// undefined if the run was superseded or cancelled; throws what went wrong.
async function runJob(kind, runs, request, finish) {
  const run = runs.start();
  const signal = runs.signal;
  showStatus(kind, 'running', `${kind === 'retime' ? 'retiming' : 'reducing'} on the server…`);
  $(`${kind}-job`).hidden = false;
  $(`${kind}-stage`).textContent = 'submitting…';
  $(`${kind}-progress`).removeAttribute('value');
  try {
    const job = await api.submitJob({...request, labels: {source: 'studio'}}, signal);  // + page=<id>
    run.jobId = job.jobId;
    showProgress(kind, job);
    await api.waitForJob(job.jobId, (snapshot) => runs.isCurrent(run) && showProgress(kind, snapshot), signal);
    const answer = await finish(job, signal);
    if (!runs.isCurrent(run)) return undefined;
    runs.stop(true);
    return {job, ...answer};
  } catch (error) {
    if (!runs.isCurrent(run)) return undefined;  // superseded or cancelled: nothing to report
    runs.stop();
    if (api.isStopped(error)) return undefined;  // the page is being left
    throw error;
  }
}

// The Cancel button: the running job is cancelled (and deleted); the page keeps the last result.
function cancelRun(kind) {
  const runs = kind === 'retime' ? retimeRuns : reduceRuns;
  if (!runs.current) return;
  runs.stop();
  const kept = kind === 'retime' ? state.retimeJob : state.reduced;
  showStatus(kind, 'cancelled', kept ? `cancelled; showing the previous result, job ${kept.jobId}` : 'cancelled');
}

// The banner's words for a run of each kind, apart from the plan's ("retime: ..."): a run's success
// clears its own failure only, never a refusal of the settings.
const RUN_WHAT = {retime: 'retime job', reduce: 'reduce job'};

// A run that failed: its status says so, with the server's words.
function showFailure(kind, error) {
  reportError(RUN_WHAT[kind], error);
  showStatus(kind, 'failed', `failed: ${describe(error)}`);
}

// ---- the retimed result (a stored job, for the preview and the downloads) -----------------------
let retimeTimer = 0;

function scheduleRetime() {
  clearTimeout(retimeTimer);
  if (!retimeRuns.current) showStatus('retime', 'pending', 'retiming soon…');
  retimeTimer = setTimeout(runRetime, RETIME_DELAY_MS);
}

// Settings refused (the server's plan, or the page's own check): nothing is retimed for them. The
// retime waiting to run is dropped and a running one stopped, so an older run ending late can
// neither show its result as the current one nor clear the refusal; the last result stays.
function refuseRetime(reason) {
  state.planRefused = true;
  clearTimeout(retimeTimer);
  retimeRuns.stop();
  const kept = state.retimeJob;
  showStatus('retime', 'invalid', kept ? `not retimed: ${reason}; showing the previous result, job ${kept.jobId}`
    : `not retimed: ${reason}`);
}

// The operation of the latest plan the server accepted, if the settings are still those.
function acceptedOp() {
  return state.plan && !state.planRefused ? state.plan.op : null;
}

function sameOp(a, b) {
  return !!a && !!b && JSON.stringify(a) === JSON.stringify(b);
}

// Retimes with the latest accepted plan's settings; the result is shown only if those are still
// the latest accepted ones when it comes (else its job is given back).
async function runRetime() {
  const clip = state.clip;
  const op = acceptedOp();
  // Settings changed since that plan: their own plan, coming, schedules the retime (or refuses).
  if (!clip || !op || !sameOp(op, retimeOperation())) return;
  const speedText = state.plan.speedText;
  const command = retimeCommand(speedText);
  let done;
  try {
    done = await runJob('retime', retimeRuns, {clipId: clip.id, operations: [{retime: op}]}, async (job, signal) => {
      // The preview reads the result as BVH; a clip without a skeleton has no figure to show.
      const [file, plan] = await Promise.all([
        hasSkeleton(clip) ? api.exportFile({jobId: job.jobId}, 'bvh', signal) : null,
        api.call('PlanRetime', {clipId: clip.id, retime: op, maxPoints: 100000}, signal),
      ]);
      return {file, plan};
    });
  } catch (error) {
    showFailure('retime', error);
    return;
  }
  if (!done) return;  // superseded by a newer edit, cancelled, or stopped by a refusal
  if (done.file) await state.previewSource;
  if (clip !== state.clip || !sameOp(op, acceptedOp())) {
    // A new clip, or settings moved on while it ran: nobody will look at this job.
    api.releaseJob(done.job.jobId);
    if (clip === state.clip && !state.planRefused && !retimeRuns.current) {
      showStatus('retime', 'pending', 'retiming soon…');
    }
    return;
  }
  const previous = state.retimeJob;
  state.retimeJob = {jobId: done.job.jobId, speedText};
  if (previous) api.releaseJob(previous.jobId);
  clearMessageOf(RUN_WHAT.retime);
  renderDownloads('downloads-retime', false);
  if (done.file) {
    try {
      preview.setResult(new TextDecoder().decode(done.file.bytes), done.plan);
    } catch (error) {
      // The job's files download as they are; the preview could not read its BVH.
      showFailure('retime', new Error(`the preview cannot show the result of job ${done.job.jobId}: ${error.message}`));
      return;
    }
    $('scrub').max = String(Math.max(preview.frameCount() - 1, 0));
  }
  showStatus('retime', 'done', `result: ${done.plan.report.outputFrameCount} frames, job ${done.job.jobId}`);
  const status = $('retime-status');
  status.dataset.jobId = done.job.jobId;
  status.dataset.speedText = speedText;
  status.dataset.command = command;
}

// ---- knots, text, holds -----------------------------------------------------------------------
function showSelectedKnot() {
  const k = editor.selectedKnot();
  if (!k) return;
  $('knot-time').value = String(k.t);
  $('knot-unit').textContent = k.unit;
  $('knot-speed').value = String(k.v);
}

// A typed field's number (NaN when blank) and its text as an error message quotes it.
function typedNumber(id) {
  return $(id).value.trim() === '' ? NaN : Number($(id).value);
}
function typed(id) {
  return $(id).value.trim() === '' ? 'a blank' : `"${$(id).value}"`;
}

// Why number field `id` (named `name` in the message) cannot be used, or '' when its number
// passes `usable`: `wanted` says what it should be. A number field's value is '' both when it is
// blank and when what is typed is no number ("1e", "--1": validity.badInput, whose text the page
// cannot read), so the two are told apart here, never both called a blank.
function numberFieldProblem(id, name, usable, wanted) {
  if ($(id).validity.badInput) return `${name}: what is typed is not a number`;
  const value = typedNumber(id);
  return Number.isFinite(value) && usable(value) ? '' : `${name} ${typed(id)} is not ${wanted}`;
}

// The typed time and speed of the selected knot. A value the editor cannot take (blank, not a
// number, a speed not above 0 or beyond the limits, a time past a neighbour's or the timeline's
// end) is refused with a message, in the words of the --speed text's errors, and the field shows
// the knot again: nothing typed is clamped silently.
function applyKnotFields() {
  const index = editor.selected;
  const time = typedNumber('knot-time');
  const speed = typedNumber('knot-speed');
  const unit = editor.selectedKnot().unit === 'f' ? 'frames' : 'seconds';
  const problem =
    numberFieldProblem('knot-time', 'time', (t) => t >= 0, `a number of ${unit} from 0`) ||
    numberFieldProblem('knot-speed', 'speed', (v) => v > 0, 'a number above 0') ||
    editor.fieldProblem(time, speed);
  if (problem) {
    showKnotError(`knot ${index + 1}: ${problem}; kept at ${knotLabel(editor.selectedKnot())}`);
    showSelectedKnot();
    return;
  }
  showKnotError('');
  editor.setSelected(time, speed);
}

function showKnotError(text) {
  $('knot-error').textContent = text;
  $('knot-error').hidden = !text;
}

function knotLabel(k) {
  return `${k.t}${k.unit}:${k.v}`;
}

// Typed --speed text: the server's parser (the CLI's) reads it, then the knots must pass the
// editor's own constraints (its speed limits, times in order), which the parser does not check.
// The error shows under the text and in the banner alike.
let speedTextSeq = 0;
// The typed text being read by the server, or null.
let speedTextReading = null;
// The typed text whose error is shown, or null.
let speedTextRefused = null;

async function applySpeedText() {
  const text = $('speed-text').value;
  // Enter and the blur after it both fire: the knots' own text, with no error shown, is not
  // applied again (it would undo newer knots); after an error any text is applied.
  if (state.plan && text === state.plan.speedText && $('speed-text-error').hidden) return;
  // Text whose error is shown is not read again (the blur after Enter would, and its answer
  // could come after a plan's that had put the knots' own text back).
  if (text === speedTextRefused && !$('speed-text-error').hidden) return;
  const seq = ++speedTextSeq;
  speedTextReading = text;
  let knots;
  try {
    const parsed = await api.call('ParseSpeedKnots', {text});
    knots = parsed.knots.map((k) => ('frames' in k.time
      ? {t: k.time.frames, unit: 'f', v: k.speed}
      : {t: k.time.seconds, unit: 's', v: k.speed}));
  } catch (error) {
    if (seq === speedTextSeq) {
      speedTextReading = null;
      if (!api.isStopped(error)) showSpeedTextError(describe(error), text);
    }
    return;
  }
  if (seq !== speedTextSeq) return;  // a newer text was typed meanwhile
  speedTextReading = null;
  const problem = editor.problemWith(knots);
  if (problem) {
    showSpeedTextError(problem, text);
    return;
  }
  showSpeedTextError('');
  editor.setKnots(knots, Math.min(editor.selected, knots.length - 1), {undoable: true});
  state.lastEdit = performance.now();
  showSelectedKnot();
  requestPlan();
}

// Shows `text` as the error of the typed text `refused` ('' clears it).
function showSpeedTextError(text, refused = null) {
  speedTextRefused = text ? refused : null;
  $('speed-text-error').textContent = text;
  $('speed-text-error').hidden = !text;
  $('speed-text').classList.toggle('invalid', !!text);
  if (text) showMessage(`--speed: ${text}`);
  else clearMessageOf('--speed');
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
  editor.showHolds(!toOutput);
  editor.setKnots(knots, editor.selected);
  editor.forgetHistory();  // the edits before were in the other domain's times
  showHoldError('');
  state.lastEdit = performance.now();
  requestPlan();
}

// The editor's holds as a list, each with its remove button (an edit undo reaches).
function renderHolds() {
  const list = $('holds');
  list.textContent = '';
  editor.holds.forEach((h, i) => {
    const item = document.createElement('span');
    item.textContent = `${h.atSeconds}s:${h.duration}`;
    const remove = document.createElement('button');
    remove.textContent = '×';
    remove.title = 'remove this hold';
    remove.addEventListener('click', () => editor.removeHold(i));
    item.appendChild(remove);
    list.appendChild(item);
  });
}

// A hold from its typed fields: a source time within the clip and a duration above 0, or the
// fields are refused with a message (never dropped without a word, never clamped).
function addHoldFromFields() {
  if (!state.clip) return;
  const at = typedNumber('hold-at');
  const duration = typedNumber('hold-duration');
  const end = +state.clip.duration.toPrecision(12);
  const problem =
    numberFieldProblem('hold-at', 'time', (t) => t >= 0, 'a number of seconds from 0') ||
    (at > state.clip.duration ? `time ${at}s is after the end of the clip (${end}s)` : '') ||
    numberFieldProblem('hold-duration', 'duration', (d) => d > 0, 'a number of seconds above 0');
  showHoldError(problem ? `hold: ${problem}; no hold added` : '');
  if (!problem) editor.addHold(at, duration);
}

function showHoldError(text) {
  $('hold-error').textContent = text;
  $('hold-error').hidden = !text;
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
  const words = fileWords('reduce', '-keys', '.anim');
  const method = $('reduce-method').value;
  if (method === 'paper' || method === 'noise') {
    words.push('--method', method);
  } else if (method === 'joint') {
    words.push('--joint-tolerance', `${Number($('joint-tolerance').value)}%`);
  } else {
    words.push('--tolerance', Number($('tolerance').value));
    if ($('position-tolerance').value.trim() !== '') {
      words.push('--position-tolerance', Number($('position-tolerance').value));
    }
  }
  return commandLine(words);
}

// Shows the inputs of the chosen method only.
function showReduceInputs() {
  const method = $('reduce-method').value;
  document.querySelectorAll('.tolerance-only').forEach((e) => (e.hidden = method !== 'tolerance'));
  document.querySelectorAll('.joint-only').forEach((e) => (e.hidden = method !== 'joint'));
}

let reduceTimer = 0;

function scheduleReduce(delay = REDUCE_DELAY_MS) {
  clearTimeout(reduceTimer);
  if (!state.clip) return;
  const method = $('reduce-method').value;
  if (method === 'tolerance' && $('tolerance').value.trim() === '') return;
  if (method === 'joint' && $('joint-tolerance').value.trim() === '') return;
  if (!reduceRuns.current) showStatus('reduce', 'pending', 'reducing soon…');
  reduceTimer = setTimeout(runReduce, delay);
}

async function runReduce() {
  const clip = state.clip;
  const op = reduceOperation();
  const command = reduceCommand();
  showReduceInputs();
  let done;
  try {
    done = await runJob('reduce', reduceRuns, {clipId: clip.id, operations: [{reduce: op}]}, async (job, signal) => ({
      result: await api.fetchResult('GetJobResult', {jobId: job.jobId}, signal),
    }));
  } catch (error) {
    showFailure('reduce', error);
    return;
  }
  if (!done) return;
  if (clip !== state.clip) {
    api.releaseJob(done.job.jobId);  // a new clip was opened while it ran
    return;
  }
  const previous = state.reduced;
  const report = done.result.reports.find((r) => r.reduction)?.reduction || {};
  state.reduced = {jobId: done.job.jobId, curves: done.result.curves, report, op};
  if (previous) api.releaseJob(previous.jobId);
  clearMessageOf(RUN_WHAT.reduce);
  $('key-count').textContent = String(report.keyCount);
  $('reduce-command').textContent = command;
  showStatus('reduce', 'done', `${report.keyCount} keys for ${report.sampleCount} samples, job ${done.job.jobId}`);
  const status = $('reduce-status');
  status.dataset.jobId = done.job.jobId;
  status.dataset.command = command;
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
    if (!hasSkeleton(state.clip) && SKELETON_FORMATS.has(format.name)) continue;
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
$('add-hold').addEventListener('click', addHoldFromFields);
// Ctrl+Z / Ctrl+Shift+Z / Ctrl+Y reach the editor's history from anywhere on the page but a field
// text is typed into (whose own undo they are) and the editor itself (which takes them): after a
// click on "add hold", a hold's ×, a checkbox or a list, the undo is at hand.
const TEXT_INPUT_TYPES = new Set(['text', 'number', 'password', 'search', 'email', 'url', 'tel']);
document.addEventListener('keydown', (e) => {
  // Alt with Ctrl is AltGr on many keyboards: a character being typed, not a shortcut.
  if (e.altKey || e.defaultPrevented) return;
  const target = e.target;
  const typedInto = target.tagName === 'TEXTAREA' || target.isContentEditable ||
      (target.tagName === 'INPUT' && TEXT_INPUT_TYPES.has(target.type));
  if (target !== $('editor') && !typedInto) editor.takeHistoryKey(e);
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
$('retime-cancel').addEventListener('click', () => cancelRun('retime'));
$('reduce-cancel').addEventListener('click', () => cancelRun('reduce'));
// Leaving the page (or freezing it in the back/forward cache) stops its calls and its jobs;
// coming back from that cache runs them again.
window.addEventListener('pagehide', () => {
  clearTimeout(retimeTimer);
  clearTimeout(reduceTimer);
  api.leave();
});
window.addEventListener('pageshow', (e) => {
  if (!e.persisted) return;
  // Its jobs cancelled on leaving, and any a stopped SubmitJob made, are released (before any
  // new job of the page is submitted).
  guarded('releasing the jobs of the page left', () => api.releaseLeftJobs());
  if (!state.clip) return;
  state.retimeJob = null;  // deleted or cancelled on leaving
  state.reduced = null;
  forgetResults();
  // The figure went with the results: the source skeleton is loaded again for the reruns.
  state.previewSource = loadPreviewSource(state.clip);
  requestPlan();
  scheduleReduce(0);
});
$('token').addEventListener('change', (e) => {
  api.setToken(e.target.value.trim());
  showMessage('token set', 'info');
  start();
});

async function start() {
  const info = await guarded('connecting', () => api.call('GetServerInfo'));
  if (!info) return;
  state.info = info;
  // The jobs earlier pages of this tab left behind (running when they were left).
  guarded('releasing the jobs of pages left', () => api.releaseLeftJobs());
  document.body.dataset.ready = 'true';
  if ($('message').className === 'info') showMessage('');
}

start();
