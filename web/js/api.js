// The studio's client of the tempokey.v1 HTTP/JSON API (README "HTTP API"): every call is a POST
// to /tempokey.v1.MotionService/<Method> with the request message in protobuf's JSON mapping;
// streaming answers come as NDJSON lines {"result": message} and may end with {"error": status}.

const SERVICE = '/tempokey.v1.MotionService/';
const TOKEN_KEY = 'tempokey.token';

export class ApiError extends Error {
  constructor(status) {
    super(status.message || status.status || 'request failed');
    this.code = status.code ?? 2;
    this.status = status.status || 'UNKNOWN';
    this.retryAfterMs = status.retryAfterMs;
    this.stopped = !!status.stopped;
  }
}

export function token() {
  return sessionStorage.getItem(TOKEN_KEY) || '';
}

export function setToken(value) {
  if (value) sessionStorage.setItem(TOKEN_KEY, value);
  else sessionStorage.removeItem(TOKEN_KEY);
}

function headers(contentType) {
  const h = {'Content-Type': contentType};
  if (token()) h.Authorization = 'Bearer ' + token();
  return h;
}

// Every call can be stopped: by its caller's signal (a newer edit supersedes the run) or by
// leaving the page. Chrome keeps a fetch's connection open after the page has gone, so without an
// abort the server goes on answering, and working, for nobody.
const calls = new Set();  // the AbortControllers of the calls in flight

function stoppedError() {
  return new ApiError({code: 1, status: 'CANCELLED', message: 'stopped by the page', stopped: true});
}

// True for the error of a call the page stopped itself (nothing to tell the user).
export function isStopped(error) {
  return error instanceof ApiError && error.stopped;
}

async function stoppable(signal, work) {
  const controller = new AbortController();
  const stop = () => controller.abort();
  if (signal) signal.addEventListener('abort', stop);
  if (signal && signal.aborted) stop();
  calls.add(controller);
  try {
    if (controller.signal.aborted) throw stoppedError();
    return await work(controller.signal);
  } catch (error) {
    throw controller.signal.aborted ? stoppedError() : error;
  } finally {
    calls.delete(controller);
    if (signal) signal.removeEventListener('abort', stop);
  }
}

async function post(method, body, contentType, signal) {
  let response;
  try {
    response = await fetch(SERVICE + method, {method: 'POST', headers: headers(contentType), body, signal});
  } catch (error) {
    if (signal.aborted) throw error;
    throw new ApiError({code: 14, status: 'UNAVAILABLE', message: 'the server cannot be reached'});
  }
  if (!response.ok) {
    let status;
    try {
      status = await response.json();
    } catch (error) {
      status = {code: 2, status: 'UNKNOWN', message: `HTTP ${response.status}`};
    }
    throw new ApiError(status);
  }
  return response;
}

// A unary call: the response message.
export function call(method, request = {}, signal = null) {
  return stoppable(signal, async (own) => {
    const response = await post(method, JSON.stringify(request), 'application/json', own);
    return response.json();
  });
}

// A call with a streamed answer: every response message, in order. `requests` is one message, or
// an array of them for client-streaming methods (sent as NDJSON).
export function stream(method, requests = {}, onMessage = null, signal = null) {
  return stoppable(signal, (own) => readStream(method, requests, onMessage, own));
}

async function readStream(method, requests, onMessage, signal) {
  const body = Array.isArray(requests)
    ? requests.map((r) => JSON.stringify(r)).join('\n') + '\n'
    : JSON.stringify(requests);
  const response = await post(method, body, Array.isArray(requests) ? 'application/x-ndjson' : 'application/json', signal);
  const reader = response.body.getReader();
  const decoder = new TextDecoder();
  const messages = [];
  let pending = '';
  const take = (line) => {
    if (!line.trim()) return;
    const item = JSON.parse(line);
    if (item.error) throw new ApiError(item.error);
    messages.push(item.result);
    if (onMessage) onMessage(item.result);
  };
  for (;;) {
    const {value, done} = await reader.read();
    if (done) break;
    pending += decoder.decode(value, {stream: true});
    let newline;
    while ((newline = pending.indexOf('\n')) >= 0) {
      take(pending.slice(0, newline));
      pending = pending.slice(newline + 1);
    }
  }
  take(pending + decoder.decode());
  return messages;
}

// ---- jobs -------------------------------------------------------------------------------------
// The jobs this page submitted and has not deleted: job id -> whether it has ended. A stored job
// costs the server memory until its TTL, so the page deletes each once it has no use for it, and
// cancels first one that is still queued or running.
const jobs = new Map();
const ENDED = new Set(['JOB_STATE_SUCCEEDED', 'JOB_STATE_FAILED', 'JOB_STATE_CANCELLED']);

export async function submitJob(request, signal = null) {
  // No job of this page is made while the jobs left by it are being listed (releaseLeftJobs):
  // one made meanwhile would look left behind.
  await sweeping;
  if (signal && signal.aborted) throw stoppedError();
  // Not stopped half-way by `signal`: only the answer names the job to cancel.
  const job = await call('SubmitJob', {...request, labels: {...request.labels, [PAGE_LABEL]: pageId}});
  jobs.set(job.jobId, ENDED.has(job.state));
  if (signal && signal.aborted) {
    releaseJob(job.jobId);
    throw stoppedError();
  }
  return job;
}

// The page no longer needs the job: cancelled if it still runs, then deleted once it has ended.
export async function releaseJob(jobId) {
  if (!jobs.has(jobId)) return;
  try {
    if (!jobs.get(jobId)) {
      const job = await call('CancelJob', {jobId});
      // A running job ends at its next stop ("cancelling"); the server deletes ended jobs only.
      if (!ENDED.has(job.state)) await stream('WatchJob', {jobId});
    }
    await call('DeleteJob', {jobId});
  } catch (error) {
    // Gone already (NOT_FOUND), or the page is leaving: leave() has told the server.
  }
  jobs.delete(jobId);
}

// The page is hidden for good or for the back/forward cache (pagehide): every call in flight is
// stopped and the server is told that no job of this page is needed any more, running ones
// cancelled and ended ones deleted. keepalive lets these requests outlive the page. A cancelled
// job cannot be deleted before it has ended, and a SubmitJob stopped here may have made its job
// anyway: this page's id is noted as left, and the next studio page of this browser tab (or this
// one, back from the back/forward cache) releases the jobs labelled with it (releaseLeftJobs).
export function leave() {
  for (const [jobId, ended] of jobs) send(ended ? 'DeleteJob' : 'CancelJob', {jobId});
  jobs.clear();
  for (const controller of calls) controller.abort();
  setLeftPages([...leftPages().filter((id) => id !== pageId), pageId]);
}

// ---- jobs of pages left -------------------------------------------------------------------------
// Every job the page submits carries the label page=<this page's id>, an id of its own (a new one
// each time the page loads). The ids of pages left are kept in sessionStorage (this tab's, this
// origin's): a page left for good leaves nothing behind for longer than its next load in the tab.
const PAGE_LABEL = 'page';
const LEFT_PAGES_KEY = 'tempokey.leftPages';
export const pageId = Array.from(crypto.getRandomValues(new Uint8Array(12)), (b) => b.toString(16).padStart(2, '0')).join('');
let sweeping = Promise.resolve();

function leftPages() {
  try {
    const ids = JSON.parse(sessionStorage.getItem(LEFT_PAGES_KEY) || '[]');
    return Array.isArray(ids) ? ids.filter((id) => typeof id === 'string') : [];
  } catch (error) {
    return [];
  }
}

function setLeftPages(ids) {
  if (ids.length) sessionStorage.setItem(LEFT_PAGES_KEY, JSON.stringify(ids));
  else sessionStorage.removeItem(LEFT_PAGES_KEY);
}

// Releases (cancels, then deletes) every job of the pages left in this tab, this page's own too
// when it comes back from the back/forward cache, that the page does not know. Resolves once they
// are listed (the releases go on); no job of this page is submitted before. Throws what ListJobs
// threw (the ids stay noted for the next try).
export function releaseLeftJobs() {
  const listing = (async () => {
    for (const id of leftPages()) {
      let pageToken = '';
      do {
        const answer = await call('ListJobs', {labels: {[PAGE_LABEL]: id}, pageSize: 1000, pageToken});
        for (const job of answer.jobs || []) {
          if (jobs.has(job.jobId)) continue;
          jobs.set(job.jobId, ENDED.has(job.state));
          releaseJob(job.jobId);
        }
        pageToken = answer.nextPageToken || '';
      } while (pageToken);
      setLeftPages(leftPages().filter((left) => left !== id));
    }
  })();
  sweeping = listing.catch(() => {});
  return listing;
}

function send(method, request) {
  fetch(SERVICE + method, {method: 'POST', headers: headers('application/json'),
    body: JSON.stringify(request), keepalive: true}).catch(() => {});
}

// Follows a job until it ends; resolves with its last snapshot (SUCCEEDED, FAILED, CANCELLED).
export async function waitForJob(jobId, onProgress = null, signal = null) {
  const snapshots = await stream('WatchJob', {jobId}, onProgress, signal);
  const last = snapshots[snapshots.length - 1];
  if (jobs.has(jobId) && ENDED.has(last.state)) jobs.set(jobId, true);
  if (last.state !== 'JOB_STATE_SUCCEEDED') {
    throw new ApiError({code: last.errorCode || 2, status: last.state, message: last.errorMessage || last.state});
  }
  return last;
}

function base64ToBytes(text) {
  const binary = atob(text);
  const bytes = new Uint8Array(binary.length);
  for (let i = 0; i < binary.length; ++i) bytes[i] = binary.charCodeAt(i);
  return bytes;
}

// ExportFile: {fileName, mediaType, bytes} of a job's result or a stored clip.
export async function exportFile(source, format, signal = null) {
  const chunks = await stream('ExportFile', {...source, format}, null, signal);
  const parts = chunks.map((c) => base64ToBytes(c.data));
  const size = parts.reduce((n, p) => n + p.length, 0);
  const bytes = new Uint8Array(size);
  let at = 0;
  for (const p of parts) {
    bytes.set(p, at);
    at += p.length;
  }
  return {fileName: chunks[0].fileName, mediaType: chunks[0].mediaType, bytes};
}

// A result stream (GetJobResult, GetClip) joined: {header, reports, channels: Float64Array[] |
// curves: [{time, value, inTangent, outTangent, inWeight, outWeight}]}.
export async function fetchResult(method, request, signal = null) {
  const parts = await stream(method, {...request, batchParts: true}, null, signal);
  const head = parts[0].header;
  const layout = head.clip || head.keyedClip;
  const frames = Number(layout.frameCount);
  const result = {header: layout, keyed: !!head.keyedClip, reports: head.reports || []};
  if (result.keyed) {
    result.curves = layout.channels.map(() => ({time: [], value: [], inTangent: [], outTangent: [], inWeight: [], outWeight: []}));
    const add = (c) => {
      const curve = result.curves[c.channelIndex];
      for (const key of ['time', 'value', 'inTangent', 'outTangent', 'inWeight', 'outWeight']) {
        const column = key === 'time' ? c.timeSeconds : c[key];
        for (const v of column) curve[key].push(v);
      }
    };
    for (const part of parts.slice(1)) {
      if (part.curves) part.curves.curves.forEach(add);
      if (part.curve) add(part.curve);
    }
  } else {
    result.channels = layout.channels.map(() => new Float64Array(frames));
    const add = (s) => result.channels[s.channelIndex].set(s.samples, Number(s.firstFrame));
    for (const part of parts.slice(1)) {
      if (part.sampleSlices) part.sampleSlices.slices.forEach(add);
      if (part.samples) add(part.samples);
    }
  }
  return result;
}

// "Hips.Xrotation" or a scalar channel's name.
export function channelName(header, index) {
  const channel = header.channels[index];
  if (channel.jointIndex === undefined || channel.jointIndex === null) return channel.name;
  const kinds = {
    CHANNEL_KIND_X_POSITION: 'Xposition', CHANNEL_KIND_Y_POSITION: 'Yposition', CHANNEL_KIND_Z_POSITION: 'Zposition',
    CHANNEL_KIND_X_ROTATION: 'Xrotation', CHANNEL_KIND_Y_ROTATION: 'Yrotation', CHANNEL_KIND_Z_ROTATION: 'Zrotation',
  };
  return header.joints[channel.jointIndex].name + '.' + (kinds[channel.kind] || channel.name);
}

export function isRotation(header, index) {
  return /ROTATION$/.test(header.channels[index].kind);
}
