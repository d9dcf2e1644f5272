// The time map t(τ) (the first paper's Figure 3) as the server computed it (PlanRetime): output
// time over source time, with the identity for reference, the knots on the curve, a band under
// the axis coloured by the local decimation ratio (blue where frames are expanded: slow motion;
// red where they are compressed: accelerated time) and a cursor at the previewed frame.
import {formatSeconds, niceStep} from './velocity_editor.js';

const PAD = {left: 48, right: 14, top: 12, bottom: 44};

export class TimeMapView {
  constructor(canvas) {
    this.canvas = canvas;
    this.plan = null;
    this.knots = [];   // [{source, output}] seconds
    this.cursor = null;  // {source, output}
    new ResizeObserver(() => this.draw()).observe(canvas);
  }

  setPlan(plan, knots) {
    this.plan = plan;
    this.knots = knots;
    this.draw();
  }

  setCursor(cursor) {
    this.cursor = cursor;
    this.draw();
  }

  draw() {
    const canvas = this.canvas;
    const w = canvas.clientWidth;
    const h = canvas.clientHeight;
    if (w === 0 || h === 0) return;
    const ratio = window.devicePixelRatio || 1;
    canvas.width = Math.round(w * ratio);
    canvas.height = Math.round(h * ratio);
    const g = canvas.getContext('2d');
    g.setTransform(ratio, 0, 0, ratio, 0, 0);
    g.clearRect(0, 0, w, h);
    const plan = this.plan;
    if (!plan) return;
    const ts = plan.sourceDurationSeconds;
    const to = plan.report.outputDurationSeconds;
    const outFrame = plan.outputFrameTimeSeconds;
    const span = Math.max(ts, to, 1e-6);
    const x0 = PAD.left;
    const x1 = w - PAD.right;
    const y0 = h - PAD.bottom;
    const y1 = PAD.top;
    const x = (tau) => x0 + (tau / ts) * (x1 - x0);
    const y = (t) => y0 - (t / span) * (y0 - y1);

    g.font = '11px system-ui, sans-serif';
    g.lineWidth = 1;
    g.strokeStyle = '#e3e6ea';
    g.fillStyle = '#6b7280';
    g.textAlign = 'center';
    g.textBaseline = 'top';
    const sx = niceStep(ts / 8);
    for (let tau = 0; tau <= ts + 1e-9; tau += sx) {
      g.beginPath();
      g.moveTo(x(tau), y0);
      g.lineTo(x(tau), y1);
      g.stroke();
      g.fillText(formatSeconds(tau), x(tau), y0 + 18);
    }
    g.textAlign = 'right';
    g.textBaseline = 'middle';
    const sy = niceStep(span / 6);
    for (let t = 0; t <= span + 1e-9; t += sy) {
      g.beginPath();
      g.moveTo(x0, y(t));
      g.lineTo(x1, y(t));
      g.stroke();
      g.fillText(formatSeconds(t), x0 - 6, y(t));
    }
    g.strokeStyle = '#9aa3ad';
    g.strokeRect(x0, y1, x1 - x0, y0 - y1);
    g.save();
    g.translate(12, (y0 + y1) / 2);
    g.rotate(-Math.PI / 2);
    g.textAlign = 'center';
    g.fillText('output time t', 0, 0);
    g.restore();
    g.textAlign = 'left';
    g.textBaseline = 'top';
    g.fillText('source time τ', x1 - 80, y0 + 30);

    // Identity (no retime) for reference.
    g.setLineDash([4, 4]);
    g.strokeStyle = '#9aa3ad';
    g.beginPath();
    g.moveTo(x(0), y(0));
    g.lineTo(x(ts), y(Math.min(ts, span)));
    g.stroke();
    g.setLineDash([]);

    // Decimation band: one strip per map point along the source axis.
    const frames = plan.outputFrames.map(Number);
    const taus = plan.sourceTimeSeconds;
    const rho = plan.decimationRatio;
    for (let i = 0; i + 1 < taus.length; ++i) {
      const a = x(Math.min(taus[i], taus[i + 1]));
      const b = x(Math.max(taus[i], taus[i + 1]));
      g.fillStyle = ratioColour(rho[i]);
      g.fillRect(a, y0 + 2, Math.max(b - a, 1), 12);
    }

    // The map itself.
    g.strokeStyle = '#0f766e';
    g.lineWidth = 2;
    g.beginPath();
    for (let i = 0; i < taus.length; ++i) {
      const px = x(taus[i]);
      const py = y(frames[i] * outFrame);
      if (i === 0) g.moveTo(px, py);
      else g.lineTo(px, py);
    }
    g.stroke();
    g.fillStyle = '#0f766e';
    for (const k of this.knots) {
      g.beginPath();
      g.arc(x(k.source), y(k.output), 3.5, 0, 2 * Math.PI);
      g.fill();
    }
    if (this.cursor) {
      g.strokeStyle = '#f59e0b';
      g.lineWidth = 1;
      g.beginPath();
      g.moveTo(x(this.cursor.source), y0);
      g.lineTo(x(this.cursor.source), y(this.cursor.output));
      g.lineTo(x0, y(this.cursor.output));
      g.stroke();
      g.fillStyle = '#f59e0b';
      g.beginPath();
      g.arc(x(this.cursor.source), y(this.cursor.output), 4.5, 0, 2 * Math.PI);
      g.fill();
    }
  }
}

// Blue for expanded (ρ < 1, slow motion), red for compressed (ρ > 1), white for unchanged; a
// hold (ρ = 0) is the deepest blue.
export function ratioColour(r) {
  const strength = r <= 0 ? 1 : Math.min(Math.abs(Math.log2(r)) / 2, 1);
  const tint = Math.round(255 * (1 - 0.75 * strength));
  return r < 1 ? `rgb(${tint}, ${tint + Math.round(40 * strength)}, 255)` : `rgb(255, ${tint}, ${tint})`;
}
