"""Mamdani fuzzy fuel model (27 rules) from the Greek fuzzy fuel-consumption work.

Inputs: ship speed 5–11 m/s, resistance 0–6 (×10⁴ N), significant wave height 0–8 m.
Output: fuel consumption 0.5–3 t/h. min for "and" and implication, max aggregation, centroid
defuzzification over 101 points of the output range (the MATLAB defaults the work used).
The wave sets as printed have medium/big swapped; here medium = trap[1,3,5,7] and
big = trap[5,7,8,8], which reproduces the published outputs.
"""

from __future__ import annotations

import numpy as np


def trapmf(x, a, b, c, d):
    """Trapezoid rising a→b, flat b→c, falling c→d (a == b or c == d: vertical shoulder)."""
    x = np.asarray(x, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        up = np.where(b > a, (x - a) / (b - a), 1.0)
        down = np.where(d > c, (d - x) / (d - c), 1.0)
    mu = np.clip(np.minimum(up, down), 0.0, 1.0)
    return np.where((x < a) | (x > d), 0.0, mu)


def trimf(x, a, b, c):
    return trapmf(x, a, b, b, c)


SPEED = {"slow": lambda x: trimf(x, 5, 5, 7), "medium": lambda x: trapmf(x, 5, 7, 9, 11), "fast": lambda x: trimf(x, 9, 11, 11)}
RESISTANCE = {"small": lambda x: trapmf(x, 0, 0, 1, 3), "medium": lambda x: trimf(x, 1, 3, 5), "big": lambda x: trapmf(x, 3, 5, 6, 6)}
WAVE = {"small": lambda x: trapmf(x, 0, 0, 1, 3), "medium": lambda x: trapmf(x, 1, 3, 5, 7), "big": lambda x: trapmf(x, 5, 7, 8, 8)}
FUEL = {"low": lambda y: trapmf(y, 0.5, 0.5, 1, 1.5), "medium": lambda y: trapmf(y, 1, 1.5, 2, 2.5), "high": lambda y: trapmf(y, 2, 2.5, 3, 3)}
FUEL_RANGE = (0.5, 3.0)
SPEED_RANGE, RESISTANCE_RANGE, WAVE_RANGE = (5.0, 11.0), (0.0, 6.0), (0.0, 8.0)  # the inputs' universes

# (speed, resistance, wave) → fuel, rules 1..27 in the order of the published tables
_OUT = {
    "medium": ["low", "low", "medium", "low", "medium", "high", "medium", "medium", "high"],
    "big": ["medium", "medium", "high", "medium", "high", "high", "medium", "high", "high"],
    "small": ["low", "low", "medium", "low", "medium", "high", "medium", "medium", "high"],
}
RULES = [(s, r, w, _OUT[w][3 * ri + si]) for w in ("medium", "big", "small")
         for ri, r in enumerate(("small", "medium", "big")) for si, s in enumerate(("slow", "medium", "fast"))]


def fuel_tph(speed_ms: float, resistance_1e4n: float, wave_m: float, n_points: int = 101) -> float:
    """Fuel consumption (t/h) for one input triple."""
    y = np.linspace(*FUEL_RANGE, n_points)
    agg = np.zeros_like(y)
    for s, r, w, out in RULES:
        strength = min(float(SPEED[s](speed_ms)), float(RESISTANCE[r](resistance_1e4n)), float(WAVE[w](wave_m)))
        if strength > 0:
            agg = np.maximum(agg, np.minimum(strength, FUEL[out](y)))
    if agg.sum() == 0:
        return float("nan")
    return float((agg * y).sum() / agg.sum())


def fired_rules(speed_ms: float, resistance_1e4n: float, wave_m: float) -> list[int]:
    """1-based numbers of the rules with non-zero firing strength (to compare with the published cases)."""
    return [i + 1 for i, (s, r, w, _) in enumerate(RULES)
            if min(float(SPEED[s](speed_ms)), float(RESISTANCE[r](resistance_1e4n)), float(WAVE[w](wave_m))) > 0]
