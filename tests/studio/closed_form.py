"""The first paper's time map in closed form, written from SPEC 3.1 for the studio tests.

Independent of the server and of the page: speed v(τ) piecewise linear over source time,
flat outside the knots; output time t(τ) = ∫ dσ / v(σ), per segment h / logmean(v0, v1) and, inside
a segment, Δt(u) = log(1 + m·u / v0) / m; the inverse τ(t) = τ_k + v_k·(exp(m·s) - 1) / m. Fit to
grid scales every speed by c so that T_o·f_o is the nearest whole number of frames.
"""

import math


def parse_speed_text(text, frame_time):
    """`0s:1,2.5s:0.5,75f:2` as [(seconds, speed)] (frames at `frame_time`)."""
    knots = []
    for part in text.split(","):
        time, speed = part.strip().split(":")
        time = time.strip()
        value = float(time[:-1])
        seconds = value * frame_time if time.endswith("f") else value
        knots.append((seconds, float(speed)))
    return knots


def segments(knots, source_duration):
    """[(tau0, tau1, v0, v1)] covering [0, source_duration], flat outside the knots."""
    points = [(0.0, knots[0][1])] + [k for k in knots if 0.0 <= k[0] <= source_duration]
    points.append((source_duration, knots[-1][1]))
    # Knots past the end: the speed at the end is interpolated on the segment that crosses it.
    for (a, va), (b, vb) in zip(knots, knots[1:]):
        if a <= source_duration < b and b > a:
            points[-1] = (source_duration, va + (vb - va) * (source_duration - a) / (b - a))
    return [(a, b, va, vb) for (a, va), (b, vb) in zip(points, points[1:]) if b > a]


def elapsed(v0, v1, h, u):
    """Output time to advance u source seconds into a segment of span h from v0 to v1."""
    m = (v1 - v0) / h
    if abs(m * u / v0) < 1e-12:
        return u / v0
    return math.log1p(m * u / v0) / m


def output_duration(knots, source_duration):
    return sum(elapsed(v0, v1, b - a, b - a) for a, b, v0, v1 in segments(knots, source_duration))


def grid_fit(knots, source_duration, output_frame_time, hold_seconds=0.0):
    """(c, frames): the fit-to-grid factor and the output frame count. Holds keep their length,
    so only the speed part is scaled."""
    raw = output_duration(knots, source_duration)
    intervals = round((raw + hold_seconds) / output_frame_time)
    fitted = intervals * output_frame_time - hold_seconds
    return raw / fitted, intervals + 1


def source_time(knots, source_duration, t, c=1.0, hold=None):
    """τ(t) with every speed scaled by c; `hold` = (source time, duration) freezes the pose."""
    if hold is not None:
        at, duration = hold
        start = output_time(knots, source_duration, at, c)
        if t <= start:
            return source_time(knots, source_duration, t, c)
        if t <= start + duration:
            return at
        return source_time(knots, source_duration, t - duration, c)
    for a, b, v0, v1 in segments(knots, source_duration):
        v0, v1 = c * v0, c * v1
        span = elapsed(v0, v1, b - a, b - a)
        if t <= span:
            m = (v1 - v0) / (b - a)
            if abs(m * t) < 1e-12:
                return a + v0 * t
            return a + v0 * math.expm1(m * t) / m
        t -= span
    return source_duration


def output_time(knots, source_duration, tau, c=1.0):
    """t(τ) with every speed scaled by c."""
    t = 0.0
    for a, b, v0, v1 in segments(knots, source_duration):
        if tau <= a:
            break
        u = min(tau, b) - a
        t += elapsed(c * v0, c * v1, b - a, u)
    return t
