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

async function post(method, body, contentType) {
  let response;
  try {
    response = await fetch(SERVICE + method, {method: 'POST', headers: headers(contentType), body});
  } catch (error) {
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
export async function call(method, request = {}) {
  const response = await post(method, JSON.stringify(request), 'application/json');
  return response.json();
}

// A call with a streamed answer: every response message, in order. `requests` is one message, or
// an array of them for client-streaming methods (sent as NDJSON).
export async function stream(method, requests = {}, onMessage = null) {
  const body = Array.isArray(requests)
    ? requests.map((r) => JSON.stringify(r)).join('\n') + '\n'
    : JSON.stringify(requests);
  const response = await post(method, body, Array.isArray(requests) ? 'application/x-ndjson' : 'application/json');
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

// Follows a job until it ends; resolves with its last snapshot (SUCCEEDED, FAILED, CANCELLED).
export async function waitForJob(jobId, onProgress = null) {
  const snapshots = await stream('WatchJob', {jobId}, onProgress);
  const last = snapshots[snapshots.length - 1];
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
export async function exportFile(source, format) {
  const chunks = await stream('ExportFile', {...source, format});
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
export async function fetchResult(method, request) {
  const parts = await stream(method, {...request, batchParts: true});
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
