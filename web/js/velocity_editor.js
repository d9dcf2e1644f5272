// The velocity editor (the first paper's Figure 5): speed over time as a piecewise-linear curve
// of knots on the clip's timeline. Speed is linear between knots and flat outside them; two
// knots at one time make a step. The y axis is logarithmic, so half and double speed sit
// symmetrically about 1.
//
// Mouse: double-click (or Ctrl+click) adds a knot, drag moves one, a click selects. Keyboard (editor focused):
// Delete removes the selected knot, arrows move it (a frame / 0.01; Shift: ten times), S
// doubles it into a step, Tab selects the next; Ctrl+Z (Cmd+Z) undoes the last edit of the
// knots, Ctrl+Shift+Z or Ctrl+Y redoes it. Times snap to 0.01 s (or whole frames for knots
// given in frames) and speeds to 0.01, unless Shift is held while dragging. Speeds are held
// within the limits [min, max]; knots cannot pass their neighbours.
//
// The editor also keeps the holds (freeze frames, by source time: addHold(), removeHold()),
// drawn where they are while the knots are over source time.
//
// Undo steps through the speed function as each edit left it, knots and holds together: a drag
// is one edit however many moves it takes, a key press, an added knot, an added or removed hold
// is one, knots set from typed text are one (setKnots with undoable), an edit that changes
// nothing is none. A new edit ends what redo could bring back; forgetHistory() starts afresh (a
// new clip, knots moved to the other time domain).
//
// The editor only edits knots and holds; what they mean (durations, the time map) is the
// server's answer, drawn by the caller through setPlan().

const PAD = {left: 48, right: 14, top: 14, bottom: 28};
const HIT_RADIUS = 8;
const VIEW_MIN = 0.05;
const VIEW_MAX = 20;
const HISTORY_LIMIT = 500;  // edits undo can go back

// Whether two knot lists are the same knots (times, units, speeds).
function sameKnots(a, b) {
  return a.length === b.length &&
      a.every((k, i) => k.t === b[i].t && k.unit === b[i].unit && k.v === b[i].v);
}

// Whether two hold lists are the same holds (source times, durations).
function sameHolds(a, b) {
  return a.length === b.length &&
      a.every((h, i) => h.atSeconds === b[i].atSeconds && h.duration === b[i].duration);
}

export class VelocityEditor {
  constructor(canvas, {onChange, onSelect}) {
    this.canvas = canvas;
    this.onChange = onChange;
    this.onSelect = onSelect;
    this.knots = [{t: 0, unit: 's', v: 1}];
    this.holds = [];          // [{atSeconds, duration}] by source time, in order
    this.holdsShown = true;   // while the knots are over source time
    this.selected = 0;
    this.duration = 1;        // x extent, seconds
    this.frameTime = 1 / 30;  // of the knots' timeline, for frame units and arrow steps
    this.minSpeed = 0.01;
    this.maxSpeed = 100;
    this.drag = null;
    this.markers = [];        // extra vertical markers [{t, label}]
    this.past = [];           // snapshots before each edit, the latest last
    this.future = [];         // snapshots undone, the next to redo last
    canvas.tabIndex = 0;
    canvas.addEventListener('pointerdown', (e) => this.pointerDown(e));
    canvas.addEventListener('pointermove', (e) => this.pointerMove(e));
    canvas.addEventListener('pointerup', (e) => this.pointerUp(e));
    canvas.addEventListener('dblclick', (e) => this.doubleClick(e));
    canvas.addEventListener('keydown', (e) => this.keyDown(e));
    new ResizeObserver(() => this.draw()).observe(canvas);
  }

  // ---- state ---------------------------------------------------------------------------------
  setTimeline(duration, frameTime) {
    this.duration = Math.max(duration, 1e-6);
    this.frameTime = frameTime;
    this.draw();
  }
  // The limits bound what drags and keys do to a knot; knots already beyond them are left as the
  // user made them (drawn in the shaded band), never rewritten.
  setLimits(minSpeed, maxSpeed) {
    this.minSpeed = minSpeed;
    this.maxSpeed = maxSpeed;
    this.draw();
  }
  // `undoable`: the knots replace the editor's as one edit (typed --speed text); otherwise as a
  // new start that undo does not reach behind when paired with forgetHistory().
  setKnots(knots, selected = 0, {undoable = false} = {}) {
    const before = this.snapshot();
    this.knots = knots.map((k) => ({...k}));
    if (undoable) this.record(before);
    this.selected = Math.min(selected, this.knots.length - 1);
    this.draw();
  }
  // The holds as a new start (a new clip), not an edit undo reaches.
  setHolds(holds) {
    this.holds = holds.map((h) => ({...h}));
    this.draw();
  }
  // Holds are drawn at their source times: not over output time.
  showHolds(shown) {
    this.holdsShown = shown;
    this.draw();
  }
  // A hold of `duration` seconds at source time `atSeconds`, after any at the same time: an edit.
  addHold(atSeconds, duration) {
    const before = this.snapshot();
    let at = this.holds.findIndex((h) => h.atSeconds > atSeconds);
    if (at < 0) at = this.holds.length;
    this.holds.splice(at, 0, {atSeconds, duration});
    this.record(before);
    this.changed();
  }
  // Removes the hold at `index` of this.holds: an edit.
  removeHold(index) {
    if (index < 0 || index >= this.holds.length) return;
    const before = this.snapshot();
    this.holds.splice(index, 1);
    this.record(before);
    this.changed();
  }
  seconds(k) {
    return k.unit === 'f' ? k.t * this.frameTime : k.t;
  }
  selectedKnot() {
    return this.knots[this.selected];
  }
  // Sets the selected knot from numbers typed by the user, in the knot's own unit (seconds or
  // frames, so typed whole frames stay whole), once fieldProblem() finds nothing wrong with them.
  setSelected(time, speed) {
    const k = this.selectedKnot();
    if (!k) return;
    const before = this.snapshot();
    k.t = time;
    k.v = speed;
    this.record(before);
    this.changed();
  }

  // ---- history -------------------------------------------------------------------------------
  snapshot() {
    return {knots: this.knots.map((k) => ({...k})), holds: this.holds.map((h) => ({...h})),
            selected: this.selected};
  }
  // Keeps `before` as the state undo returns to, unless the knots and holds are as they were.
  record(before) {
    if (sameKnots(before.knots, this.knots) && sameHolds(before.holds, this.holds)) return false;
    this.past.push(before);
    if (this.past.length > HISTORY_LIMIT) this.past.shift();
    this.future = [];
    return true;
  }
  undo() {
    return this.travel(this.past, this.future);
  }
  redo() {
    return this.travel(this.future, this.past);
  }
  travel(from, to) {
    if (from.length === 0) return false;
    to.push(this.snapshot());
    const {knots, holds, selected} = from.pop();
    // An edit of the holds alone leaves the selection where the user has put it since.
    if (!sameKnots(knots, this.knots)) this.selected = Math.min(selected, knots.length - 1);
    this.knots = knots;
    this.holds = holds;
    this.changed();
    return true;
  }
  // Ctrl+Z (Cmd+Z) undoes, Ctrl+Shift+Z or Ctrl+Y redoes: whether `e` is one of them, taken.
  takeHistoryKey(e) {
    const key = e.key.toLowerCase();
    if (!(e.ctrlKey || e.metaKey) || (key !== 'z' && key !== 'y')) return false;
    e.preventDefault();
    if (key === 'z' && !e.shiftKey) this.undo();
    else this.redo();
    return true;
  }
  forgetHistory() {
    this.past = [];
    this.future = [];
  }
  // Why `knots` (typed, e.g. as --speed text) cannot be this editor's, or '': every knot must be
  // one the mouse and keys could make, a finite time from 0 not before the previous knot's and a
  // speed within the limits.
  problemWith(knots) {
    let previous = 0;
    for (let i = 0; i < knots.length; ++i) {
      const k = knots[i];
      const problem = this.knotProblem(k, previous, null);
      if (problem) return `speed knot ${i + 1} (${k.t}${k.unit}:${k.v}): ${problem}`;
      previous = this.seconds(k);
    }
    return knots.length ? '' : 'no knots';
  }
  // Why the selected knot cannot take `time` (in its own unit) and `speed` typed in its fields,
  // in problemWith's words, or '': it cannot pass its neighbours, nor the timeline's end if it is
  // the last, and its speed must be within the limits (nothing typed is clamped silently).
  fieldProblem(time, speed) {
    const i = this.selected;
    const previous = i > 0 ? this.seconds(this.knots[i - 1]) : 0;
    const next = i < this.knots.length - 1
      ? {seconds: this.seconds(this.knots[i + 1]), what: "the next knot's"}
      : {seconds: this.duration, what: `the end of the timeline (${+this.duration.toPrecision(12)}s)`};
    return this.knotProblem({t: time, unit: this.knots[i].unit, v: speed}, previous, next);
  }
  // Why knot `k` cannot be the editor's: its time (seconds) not from 0, before `previous` or
  // after `next` ({seconds, what}, or null: no bound), or its speed outside the limits.
  knotProblem(k, previous, next) {
    const seconds = this.seconds(k);
    const time = `time ${k.t}${k.unit}`;
    if (!Number.isFinite(seconds) || seconds < 0) return `${time} is not a time from 0`;
    if (seconds < previous) return `${time} is before the previous knot's`;
    if (next && seconds > next.seconds) return `${time} is after ${next.what}`;
    if (!Number.isFinite(k.v) || k.v < this.minSpeed || k.v > this.maxSpeed) {
      return `speed ${k.v} is outside the limits [${this.minSpeed}, ${this.maxSpeed}]`;
    }
    return '';
  }
  clampSpeed(v) {
    return Math.min(Math.max(v, this.minSpeed), this.maxSpeed);
  }
  // A knot's time `value`, in the knot's own `unit`, kept between its neighbours' (equal is a
  // step) and inside the timeline. Clamped in that unit, a neighbour of the same unit bounding it
  // exactly: a knot in frames never picks up a frame time's rounding (61 stays 61, not
  // 61.00000000000001).
  clampTime(index, value, unit) {
    const inUnit = (seconds) => (unit === 'f' ? seconds / this.frameTime : seconds);
    const bound = (k) => (k.unit === unit ? k.t : inUnit(this.seconds(k)));
    const lo = index > 0 ? bound(this.knots[index - 1]) : 0;
    const hi = index < this.knots.length - 1 ? bound(this.knots[index + 1]) : inUnit(this.duration);
    return Math.min(Math.max(value, lo), Math.max(lo, hi));
  }
  changed() {
    this.draw();
    this.onChange(this.knots);
    this.onSelect(this.selected);
  }

  // ---- geometry ------------------------------------------------------------------------------
  viewRange() {
    let lo = Math.max(this.minSpeed, VIEW_MIN);
    let hi = Math.min(this.maxSpeed, VIEW_MAX);
    for (const k of this.knots) {
      lo = Math.min(lo, k.v);
      hi = Math.max(hi, k.v);
    }
    return [lo / 1.25, hi * 1.25];
  }
  size() {
    return {w: this.canvas.clientWidth, h: this.canvas.clientHeight};
  }
  x(seconds) {
    const {w} = this.size();
    return PAD.left + (seconds / this.duration) * (w - PAD.left - PAD.right);
  }
  y(speed) {
    const {h} = this.size();
    const [lo, hi] = this.viewRange();
    const f = (Math.log(speed) - Math.log(lo)) / (Math.log(hi) - Math.log(lo));
    return h - PAD.bottom - f * (h - PAD.top - PAD.bottom);
  }
  timeAt(px) {
    const {w} = this.size();
    return ((px - PAD.left) / (w - PAD.left - PAD.right)) * this.duration;
  }
  speedAt(py) {
    const {h} = this.size();
    const [lo, hi] = this.viewRange();
    const f = (h - PAD.bottom - py) / (h - PAD.top - PAD.bottom);
    return Math.exp(Math.log(lo) + f * (Math.log(hi) - Math.log(lo)));
  }
  hit(px, py) {
    let best = -1;
    let bestDistance = HIT_RADIUS;
    this.knots.forEach((k, i) => {
      const d = Math.hypot(this.x(this.seconds(k)) - px, this.y(k.v) - py);
      if (d <= bestDistance) {
        best = i;
        bestDistance = d;
      }
    });
    return best;
  }
  local(e) {
    const r = this.canvas.getBoundingClientRect();
    return [e.clientX - r.left, e.clientY - r.top];
  }

  // ---- input ---------------------------------------------------------------------------------
  pointerDown(e) {
    this.canvas.focus();
    const [px, py] = this.local(e);
    const i = this.hit(px, py);
    if (i < 0) {
      if (e.ctrlKey || e.metaKey) this.addAt(px, py, false);
      return;
    }
    this.selected = i;
    this.drag = {index: i, moved: false, before: this.snapshot(), recorded: false};
    this.canvas.setPointerCapture(e.pointerId);
    this.onSelect(i);
    this.draw();
  }
  pointerMove(e) {
    if (!this.drag) return;
    const [px, py] = this.local(e);
    const k = this.knots[this.drag.index];
    // The time in the knot's own unit (frames or seconds), snapped in that unit.
    let time = k.unit === 'f' ? this.timeAt(px) / this.frameTime : this.timeAt(px);
    let speed = this.speedAt(py);
    if (!e.shiftKey) {
      time = k.unit === 'f' ? Math.round(time) : Math.round(time * 100) / 100;
      speed = Math.round(speed * 100) / 100;
    }
    k.t = this.clampTime(this.drag.index, time, k.unit);
    if (k.unit === 'f' && !e.shiftKey) k.t = Math.round(k.t);
    k.v = this.clampSpeed(speed);
    this.drag.moved = true;
    if (!this.drag.recorded) this.drag.recorded = this.record(this.drag.before);
    this.changed();
  }
  pointerUp(e) {
    if (!this.drag) return;
    this.canvas.releasePointerCapture(e.pointerId);
    this.drag = null;
  }
  doubleClick(e) {
    const [px, py] = this.local(e);
    if (this.hit(px, py) >= 0) return;
    this.addAt(px, py, e.shiftKey);
  }
  // A new knot at canvas point (px, py), snapped unless `free`.
  addAt(px, py, free) {
    let seconds = Math.min(Math.max(this.timeAt(px), 0), this.duration);
    let speed = this.speedAt(py);
    if (!free) {
      seconds = Math.round(seconds * 100) / 100;
      speed = Math.round(speed * 100) / 100;
    }
    const knot = {t: seconds, unit: 's', v: this.clampSpeed(speed)};
    let at = this.knots.findIndex((k) => this.seconds(k) > seconds);
    if (at < 0) at = this.knots.length;
    const before = this.snapshot();
    this.knots.splice(at, 0, knot);
    this.selected = at;
    this.record(before);
    this.changed();
  }
  keyDown(e) {
    const k = this.selectedKnot();
    if (!k) return;
    if (this.takeHistoryKey(e)) return;
    const big = e.shiftKey ? 10 : 1;
    const before = this.snapshot();
    let handled = true;
    switch (e.key) {
      case 'Delete':
      case 'Backspace':
        if (this.knots.length > 1) {
          this.knots.splice(this.selected, 1);
          this.selected = Math.min(this.selected, this.knots.length - 1);
        }
        break;
      case 'ArrowLeft':
      case 'ArrowRight': {
        // A frame: 1 for a knot in frames, the frame time for one in seconds.
        const step = (e.key === 'ArrowLeft' ? -1 : 1) * big * (k.unit === 'f' ? 1 : this.frameTime);
        k.t = this.clampTime(this.selected, k.t + step, k.unit);
        break;
      }
      case 'ArrowUp':
      case 'ArrowDown': {
        const step = (e.key === 'ArrowDown' ? -1 : 1) * big * 0.01;
        k.v = this.clampSpeed(Math.round((k.v + step) * 100) / 100);
        break;
      }
      case 's':
      case 'S':
        this.knots.splice(this.selected + 1, 0, {...k});
        this.selected += 1;
        break;
      case 'Tab':
        this.selected = (this.selected + (e.shiftKey ? this.knots.length - 1 : 1)) % this.knots.length;
        this.onSelect(this.selected);
        this.draw();
        e.preventDefault();
        return;
      default:
        handled = false;
    }
    if (handled) {
      e.preventDefault();
      this.record(before);
      this.changed();
    }
  }

  // ---- drawing -------------------------------------------------------------------------------
  draw() {
    const canvas = this.canvas;
    const {w, h} = this.size();
    if (w === 0 || h === 0) return;
    const ratio = window.devicePixelRatio || 1;
    canvas.width = Math.round(w * ratio);
    canvas.height = Math.round(h * ratio);
    const g = canvas.getContext('2d');
    g.setTransform(ratio, 0, 0, ratio, 0, 0);
    g.clearRect(0, 0, w, h);
    const [lo, hi] = this.viewRange();
    const x0 = PAD.left;
    const x1 = w - PAD.right;
    const yTop = PAD.top;
    const yBottom = h - PAD.bottom;

    // Speed limits: the region beyond them is hatched.
    g.fillStyle = 'rgba(200, 60, 60, 0.12)';
    if (this.maxSpeed < hi) g.fillRect(x0, yTop, x1 - x0, this.y(this.maxSpeed) - yTop);
    if (this.minSpeed > lo) g.fillRect(x0, this.y(this.minSpeed), x1 - x0, yBottom - this.y(this.minSpeed));

    // Grid: speeds 1-2-5 per decade, times every "nice" step.
    g.font = '11px system-ui, sans-serif';
    g.strokeStyle = '#e3e6ea';
    g.fillStyle = '#6b7280';
    g.lineWidth = 1;
    g.textAlign = 'right';
    g.textBaseline = 'middle';
    for (let decade = -3; decade <= 3; ++decade) {
      for (const m of [1, 2, 5]) {
        const v = m * 10 ** decade;
        if (v < lo || v > hi) continue;
        const y = this.y(v);
        g.strokeStyle = v === 1 ? '#9aa3ad' : '#e3e6ea';
        g.beginPath();
        g.moveTo(x0, y);
        g.lineTo(x1, y);
        g.stroke();
        g.fillText(v + '×', x0 - 6, y);
      }
    }
    const step = niceStep(this.duration / 8);
    g.textAlign = 'center';
    g.textBaseline = 'top';
    g.strokeStyle = '#e3e6ea';
    for (let t = 0; t <= this.duration + 1e-9; t += step) {
      const x = this.x(t);
      g.beginPath();
      g.moveTo(x, yTop);
      g.lineTo(x, yBottom);
      g.stroke();
      g.fillText(formatSeconds(t), x, yBottom + 6);
    }
    g.strokeStyle = '#9aa3ad';
    g.strokeRect(x0, yTop, x1 - x0, yBottom - yTop);

    // Holds (freeze frames) at their source times.
    for (const hold of this.holdsShown ? this.holds : []) {
      const x = this.x(hold.atSeconds);
      g.fillStyle = 'rgba(234, 145, 30, 0.25)';
      g.fillRect(x - 3, yTop, 6, yBottom - yTop);
      g.fillStyle = '#b45309';
      g.textAlign = 'left';
      g.fillText(`hold ${hold.duration}s`, x + 5, yTop + 2);
    }
    for (const marker of this.markers) {
      const x = this.x(marker.t);
      g.strokeStyle = '#2563eb';
      g.setLineDash([3, 3]);
      g.beginPath();
      g.moveTo(x, yTop);
      g.lineTo(x, yBottom);
      g.stroke();
      g.setLineDash([]);
    }

    // The curve: flat before the first knot and after the last, linear in speed between knots
    // (curved on the log axis, so each segment is drawn through sub-points).
    g.strokeStyle = '#0f766e';
    g.lineWidth = 2;
    g.beginPath();
    const first = this.knots[0];
    g.moveTo(x0, this.y(first.v));
    g.lineTo(this.x(this.seconds(first)), this.y(first.v));
    for (let i = 1; i < this.knots.length; ++i) {
      const a = this.knots[i - 1];
      const b = this.knots[i];
      const ta = this.seconds(a);
      const tb = this.seconds(b);
      for (let s = 1; s <= 24; ++s) {
        const f = s / 24;
        g.lineTo(this.x(ta + f * (tb - ta)), this.y(a.v + f * (b.v - a.v)));
      }
    }
    const last = this.knots[this.knots.length - 1];
    g.lineTo(x1, this.y(last.v));
    g.stroke();

    this.knots.forEach((k, i) => {
      const x = this.x(this.seconds(k));
      const y = this.y(k.v);
      g.beginPath();
      g.arc(x, y, i === this.selected ? 6 : 4.5, 0, 2 * Math.PI);
      g.fillStyle = i === this.selected ? '#f59e0b' : '#0f766e';
      g.fill();
      g.strokeStyle = '#ffffff';
      g.lineWidth = 1.5;
      g.stroke();
    });
  }
}

export function niceStep(raw) {
  const p = 10 ** Math.floor(Math.log10(raw));
  for (const m of [1, 2, 5, 10]) if (m * p >= raw) return m * p;
  return 10 * p;
}

export function formatSeconds(t) {
  return (Math.abs(t) < 1e-9 ? 0 : +t.toFixed(3)) + 's';
}
