// The key-reduction view (the papers' Figures 4 and 6): one channel's source samples, the fitted
// curve drawn from its keys as the cubic Bezier segments the keys define (README "Keyed clip
// JSON": handles at weight x segment length, slope x that; unweighted = 1/3), the keys with their
// tangent handles, the error band (± the bound the fit kept, or ± the channel's max error for
// the paper's method, which keeps no bound) and the worst frame. The canvas draws the Beziers
// itself (bezierCurveTo), so nothing here evaluates a curve.
//
// Wheel zooms time around the pointer, drag pans, double-click shows the whole clip.

const PAD = {left: 56, right: 14, top: 14, bottom: 28};

export class CurveView {
  constructor(canvas) {
    this.canvas = canvas;
    this.data = null;
    this.view = null;
    this.drag = null;
    canvas.addEventListener('wheel', (e) => this.wheel(e), {passive: false});
    canvas.addEventListener('pointerdown', (e) => {
      this.drag = {x: e.clientX, view: [...this.view]};
      canvas.setPointerCapture(e.pointerId);
    });
    canvas.addEventListener('pointermove', (e) => this.pan(e));
    canvas.addEventListener('pointerup', () => (this.drag = null));
    canvas.addEventListener('dblclick', () => {
      if (this.data) this.view = [0, this.data.duration];
      this.draw();
    });
    new ResizeObserver(() => this.draw()).observe(canvas);
  }

  // data: {samples (Float64Array), frameTime, rotation, curve (columns) | null, bound | null,
  //        worstFrame | null, unit}
  set(data) {
    const keepView = this.data && this.view && Math.abs(this.data.duration - data.duration) < 1e-9;
    data.duration = (data.samples.length - 1) * data.frameTime;
    this.data = data;
    this.values = data.rotation ? unwrapNear(data.samples, data.curve ? data.curve.value[0] : null) : data.samples;
    if (!keepView) this.view = [0, data.duration];
    this.draw();
  }

  wheel(e) {
    if (!this.data) return;
    e.preventDefault();
    const [t0, t1] = this.view;
    const at = this.timeAt(e.clientX - this.canvas.getBoundingClientRect().left);
    const scale = Math.exp(e.deltaY * 0.002);
    const span = Math.min(Math.max((t1 - t0) * scale, this.data.frameTime * 8), this.data.duration);
    const f = (at - t0) / (t1 - t0);
    let a = at - f * span;
    a = Math.min(Math.max(a, 0), this.data.duration - span);
    this.view = [a, a + span];
    this.draw();
  }

  pan(e) {
    if (!this.drag || !this.data) return;
    const w = this.canvas.clientWidth - PAD.left - PAD.right;
    const [t0, t1] = this.drag.view;
    const dt = ((e.clientX - this.drag.x) / w) * (t1 - t0);
    const a = Math.min(Math.max(t0 - dt, 0), this.data.duration - (t1 - t0));
    this.view = [a, a + (t1 - t0)];
    this.draw();
  }

  timeAt(px) {
    const w = this.canvas.clientWidth;
    const [t0, t1] = this.view;
    return t0 + ((px - PAD.left) / (w - PAD.left - PAD.right)) * (t1 - t0);
  }

  draw() {
    const canvas = this.canvas;
    const w = canvas.clientWidth;
    const h = canvas.clientHeight;
    if (!w || !h) return;
    const ratio = window.devicePixelRatio || 1;
    canvas.width = Math.round(w * ratio);
    canvas.height = Math.round(h * ratio);
    const g = canvas.getContext('2d');
    g.setTransform(ratio, 0, 0, ratio, 0, 0);
    g.clearRect(0, 0, w, h);
    if (!this.data) return;
    const d = this.data;
    const [t0, t1] = this.view;
    const first = Math.max(0, Math.floor(t0 / d.frameTime));
    const last = Math.min(d.samples.length - 1, Math.ceil(t1 / d.frameTime));
    const curve = d.curve;
    const band = d.bound || 0;
    let lo = Infinity;
    let hi = -Infinity;
    for (let i = first; i <= last; ++i) {
      lo = Math.min(lo, this.values[i]);
      hi = Math.max(hi, this.values[i]);
    }
    if (curve) {
      for (let k = 0; k < curve.time.length; ++k) {
        if (curve.time[k] >= t0 && curve.time[k] <= t1) {
          lo = Math.min(lo, curve.value[k] - band);
          hi = Math.max(hi, curve.value[k] + band);
        }
      }
    }
    if (!(hi > lo)) {
      lo -= 1;
      hi += 1;
    }
    const margin = (hi - lo) * 0.08;
    lo -= margin;
    hi += margin;
    const x = (t) => PAD.left + ((t - t0) / (t1 - t0)) * (w - PAD.left - PAD.right);
    const y = (v) => h - PAD.bottom - ((v - lo) / (hi - lo)) * (h - PAD.top - PAD.bottom);

    g.font = '11px system-ui, sans-serif';
    g.fillStyle = '#6b7280';
    g.strokeStyle = '#e3e6ea';
    g.lineWidth = 1;
    g.textAlign = 'right';
    g.textBaseline = 'middle';
    const vs = nice((hi - lo) / 6);
    for (let v = Math.ceil(lo / vs) * vs; v <= hi; v += vs) {
      g.beginPath();
      g.moveTo(PAD.left, y(v));
      g.lineTo(w - PAD.right, y(v));
      g.stroke();
      g.fillText(+v.toFixed(6) + (d.unit || ''), PAD.left - 6, y(v));
    }
    g.textAlign = 'center';
    g.textBaseline = 'top';
    const ts = nice((t1 - t0) / 8);
    for (let t = Math.ceil(t0 / ts) * ts; t <= t1 + 1e-9; t += ts) {
      g.beginPath();
      g.moveTo(x(t), PAD.top);
      g.lineTo(x(t), h - PAD.bottom);
      g.stroke();
      g.fillText(+t.toFixed(4) + 's', x(t), h - PAD.bottom + 6);
    }
    g.save();
    g.beginPath();
    g.rect(PAD.left, PAD.top, w - PAD.left - PAD.right, h - PAD.top - PAD.bottom);
    g.clip();

    if (curve && curve.time.length > 0) {
      // Error band: the curve shifted by ±band, filled between.
      if (band > 0) {
        g.fillStyle = 'rgba(15, 118, 110, 0.14)';
        g.beginPath();
        this.tracePath(g, x, y, band, false);
        this.tracePath(g, x, y, -band, true);
        g.closePath();
        g.fill();
      }
    }
    // Source samples.
    g.fillStyle = '#334155';
    const dot = Math.max(1.2, Math.min(2.5, (w / (last - first + 1)) * 0.35));
    for (let i = first; i <= last; ++i) {
      g.fillRect(x(i * d.frameTime) - dot / 2, y(this.values[i]) - dot / 2, dot, dot);
    }
    if (curve && curve.time.length > 0) {
      g.strokeStyle = '#0f766e';
      g.lineWidth = 2;
      g.beginPath();
      this.tracePath(g, x, y, 0, false);
      g.stroke();
      // Keys and tangent handles.
      for (let k = 0; k < curve.time.length; ++k) {
        const kx = x(curve.time[k]);
        const ky = y(curve.value[k]);
        if (kx < PAD.left - 20 || kx > w + 20) continue;
        g.strokeStyle = 'rgba(168, 85, 247, 0.55)';
        g.lineWidth = 1;
        for (const [hx, hv] of this.handles(k)) {
          g.beginPath();
          g.moveTo(kx, ky);
          g.lineTo(x(hx), y(hv));
          g.stroke();
          g.beginPath();
          g.arc(x(hx), y(hv), 2, 0, 2 * Math.PI);
          g.stroke();
        }
        g.fillStyle = '#f59e0b';
        g.fillRect(kx - 3.5, ky - 3.5, 7, 7);
      }
    }
    if (d.worstFrame !== null && d.worstFrame !== undefined) {
      const wx = x(d.worstFrame * d.frameTime);
      g.strokeStyle = '#dc2626';
      g.setLineDash([4, 3]);
      g.beginPath();
      g.moveTo(wx, PAD.top);
      g.lineTo(wx, h - PAD.bottom);
      g.stroke();
      g.setLineDash([]);
      g.beginPath();
      g.arc(wx, y(this.values[d.worstFrame]), 5, 0, 2 * Math.PI);
      g.stroke();
    }
    g.restore();
    g.strokeStyle = '#9aa3ad';
    g.strokeRect(PAD.left, PAD.top, w - PAD.left - PAD.right, h - PAD.top - PAD.bottom);
  }

  // A key's handle ends: [(time, value)] before and after it.
  handles(k) {
    const c = this.data.curve;
    const out = [];
    if (k > 0) {
      const span = c.time[k] - c.time[k - 1];
      const wIn = c.inWeight.length ? c.inWeight[k] : 1 / 3;
      out.push([c.time[k] - wIn * span, c.value[k] - c.inTangent[k] * wIn * span]);
    }
    if (k + 1 < c.time.length) {
      const span = c.time[k + 1] - c.time[k];
      const wOut = c.outWeight.length ? c.outWeight[k] : 1 / 3;
      out.push([c.time[k] + wOut * span, c.value[k] + c.outTangent[k] * wOut * span]);
    }
    return out;
  }

  // The curve (shifted by `offset`) as canvas path segments, constant outside its keys;
  // `reverse` traces it right to left (for closing the band).
  tracePath(g, x, y, offset, reverse) {
    const c = this.data.curve;
    const n = c.time.length;
    const segments = [];
    for (let k = 0; k + 1 < n; ++k) {
      const span = c.time[k + 1] - c.time[k];
      const wOut = c.outWeight.length ? c.outWeight[k] : 1 / 3;
      const wIn = c.inWeight.length ? c.inWeight[k + 1] : 1 / 3;
      segments.push([
        [c.time[k], c.value[k]],
        [c.time[k] + wOut * span, c.value[k] + c.outTangent[k] * wOut * span],
        [c.time[k + 1] - wIn * span, c.value[k + 1] - c.inTangent[k + 1] * wIn * span],
        [c.time[k + 1], c.value[k + 1]],
      ]);
    }
    const p = (point) => [x(point[0]), y(point[1] + offset)];
    const start = [0, c.value[0]];
    const end = [this.data.duration, c.value[n - 1]];
    if (!reverse) {
      g.moveTo(...p(start));
      g.lineTo(...p([c.time[0], c.value[0]]));
      for (const [, a, b, e] of segments) g.bezierCurveTo(...p(a), ...p(b), ...p(e));
      g.lineTo(...p(end));
    } else {
      g.lineTo(...p(end));
      g.lineTo(...p([c.time[n - 1], c.value[n - 1]]));
      for (let s = segments.length - 1; s >= 0; --s) {
        const [b0, a, b] = segments[s];
        g.bezierCurveTo(...p(b), ...p(a), ...p(b0));
      }
      g.lineTo(...p(start));
    }
  }
}

// Angles made continuous (each within 180° of the one before), the whole run then moved by
// whole turns to lie nearest `anchor` at its start: the unwrapped angles key reduction fits.
export function unwrapNear(samples, anchor) {
  const out = new Float64Array(samples.length);
  let shift = 0;
  for (let i = 0; i < samples.length; ++i) {
    if (i > 0) {
      const step = samples[i] + shift - out[i - 1];
      shift -= 360 * Math.round(step / 360);
    }
    out[i] = samples[i] + shift;
  }
  if (anchor !== null && anchor !== undefined && out.length) {
    const turns = Math.round((anchor - out[0]) / 360);
    if (turns) for (let i = 0; i < out.length; ++i) out[i] += 360 * turns;
  }
  return out;
}

function nice(raw) {
  const p = 10 ** Math.floor(Math.log10(raw));
  for (const m of [1, 2, 5, 10]) if (m * p >= raw) return m * p;
  return 10 * p;
}
