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
  // Not stopped half-way by `signal`: only the answer names the job to cancel.
  const job = await call('SubmitJob', request);
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
// cancelled (they are deleted with the server's job TTL: a delete must wait for their end) and
// ended ones deleted. keepalive lets these requests outlive the page.
export function leave() {
  for (const [jobId, ended] of jobs) send(ended ? 'DeleteJob' : 'CancelJob', {jobId});
  jobs.clear();
  for (const controller of calls) controller.abort();
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
