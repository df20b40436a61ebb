"""
Trapezoidal motion of a linear axis: the profile a stage firmware runs, in SI units.

From rest to rest: accelerate at a up to v, cruise, decelerate at a; a short move never
reaches v (a triangle). The driver uses it for the time a move should take (a move that takes
much longer has stalled or slipped), the emulator for where its axis is at any moment.
"""

import math


def move_time_s(distance_m, max_speed_m_s, accel_m_s2):
    """Return the time (s) of a rest-to-rest move of |distance_m| (m)."""
    d = abs(distance_m)
    if not (max_speed_m_s > 0 and accel_m_s2 > 0):
        raise ValueError('speed and acceleration must be positive')
    if d * accel_m_s2 >= max_speed_m_s ** 2:       # reaches the top speed
        return d / max_speed_m_s + max_speed_m_s / accel_m_s2
    return 2.0 * math.sqrt(d / accel_m_s2)


def position_at(t_s, start_m, target_m, max_speed_m_s, accel_m_s2):
    """Return (position m, velocity m/s) t_s after a move from start_m to target_m began."""
    d = target_m - start_m
    sign, d = (1.0 if d >= 0 else -1.0), abs(d)
    total = move_time_s(d, max_speed_m_s, accel_m_s2)
    if d == 0 or t_s >= total:
        return target_m, 0.0
    t = max(t_s, 0.0)
    peak = min(max_speed_m_s, math.sqrt(d * accel_m_s2))  # the triangle's top, or v
    ramp = peak / accel_m_s2
    if t < ramp:
        s, v = 0.5 * accel_m_s2 * t * t, accel_m_s2 * t
    elif t < total - ramp:
        s, v = 0.5 * peak * ramp + peak * (t - ramp), peak
    else:
        left = total - t
        s, v = d - 0.5 * accel_m_s2 * left * left, accel_m_s2 * left
    return start_m + sign * s, sign * v
