"""`PerformanceModel`: the one interface routing uses for a vessel's speed and fuel.

A model is a form (see `features`) plus one coefficient vector per target. Routing kernels
take `form_id`, `speed_coef`, `fuel_coef` and `months_dd` as plain values and call
`features.stw_kn_nb` / `features.fuel_tph_nb`; Python code uses the vectorised methods.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field

import numpy as np

from pipeline.performance import features


DAYS_PER_MONTH = 365.25 / 12


@dataclass(frozen=True)
class PerformanceModel:
    form: str  # "thesis" | "physical"
    speed_coef: np.ndarray
    fuel_coef: np.ndarray
    months_dd: float = 0.0  # months since dry dock at the time of routing
    imo: int | None = None
    version: int | None = None
    meta: dict = field(default_factory=dict, compare=False)
    envelope: dict | None = field(default=None, compare=False)  # conditions fitted on (`sanity.Envelope` JSON); None: unknown
    data_to_utc: str | None = field(default=None, compare=False)  # newest report fitted on (ISO, UTC): months_dd's date

    def __post_init__(self):
        fid = features.FORM_IDS.get(self.form)
        if fid is None:
            raise ValueError(f"unknown performance model form {self.form!r}; use one of {sorted(features.FORM_IDS)}")
        object.__setattr__(self, "speed_coef", np.ascontiguousarray(self.speed_coef, dtype=np.float64))
        object.__setattr__(self, "fuel_coef", np.ascontiguousarray(self.fuel_coef, dtype=np.float64))
        if self.speed_coef.shape != (features.N_SPEED[fid],) or self.fuel_coef.shape != (features.N_FUEL[fid],):
            raise ValueError(
                f"{self.form} model of vessel {self.imo} needs {features.N_SPEED[fid]} speed and "
                f"{features.N_FUEL[fid]} fuel coefficients, got {self.speed_coef.shape} and {self.fuel_coef.shape}"
            )

    @property
    def form_id(self) -> int:
        return features.FORM_IDS[self.form]

    def stw_kn(self, rpm, draft_m, trim_m, wind_kn=0.0, wind_rel_deg=0.0, hs_m=0.0, wave_rel_deg=0.0):
        """Speed through water (kn), vectorised over broadcastable inputs: what routing gets (`features.stw_kn_nb`)."""
        return self._predict("speed", self.speed_coef, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg)

    def fuel_tph(self, rpm, draft_m, trim_m, wind_kn=0.0, wind_rel_deg=0.0, hs_m=0.0, wave_rel_deg=0.0):
        """Fuel rate (t/h), vectorised over broadcastable inputs: what routing gets (`features.fuel_tph_nb`)."""
        return self._predict("fuel", self.fuel_coef, rpm, draft_m, trim_m, wind_kn, wind_rel_deg, hs_m, wave_rel_deg)

    def _predict(self, target, coef, *inputs):
        shape = np.broadcast_shapes(*(np.shape(a) for a in inputs))
        return features.predict(self.form_id, target, coef, *inputs, self.months_dd).reshape(shape)

    def to_json(self) -> dict:
        return {"form": self.form, "speed_coef": self.speed_coef.tolist(), "fuel_coef": self.fuel_coef.tolist(),
                "months_dd": self.months_dd, "imo": self.imo, "version": self.version, "envelope": self.envelope,
                "data_to_utc": self.data_to_utc}

    @classmethod
    def from_json(cls, d: dict) -> "PerformanceModel":
        return cls(form=d["form"], speed_coef=np.asarray(d["speed_coef"]), fuel_coef=np.asarray(d["fuel_coef"]),
                   months_dd=float(d.get("months_dd", 0.0)), imo=d.get("imo"), version=d.get("version"),
                   envelope=d.get("envelope"), data_to_utc=d.get("data_to_utc"))

    def fouled_at(self, when_utc) -> "PerformanceModel":
        """This model with the months since dry dock it will have at `when_utc` (naive UTC): those of its newest
        report plus the time since (routing plans a voyage with the hull as it will be then, not as it was)."""
        if self.data_to_utc is None or when_utc is None:
            return self
        days = (np.datetime64(when_utc, "s") - np.datetime64(self.data_to_utc, "s")) / np.timedelta64(1, "D")
        if not np.isfinite(days) or days <= 0:
            return self
        return dataclasses.replace(self, months_dd=self.months_dd + float(days) / DAYS_PER_MONTH)

    def outside_envelope(self, rpm: float, draft_m: float, wind_kn: float = 0.0, hs_m: float = 0.0) -> list[str]:
        """What of the conditions lies outside those the model was fitted on (['rpm 130 > 122', …]); [] inside or
        when the envelope is unknown."""
        from pipeline.performance.sanity import Envelope

        env = Envelope.from_json(self.envelope)
        return env.outside(rpm, draft_m, wind_kn, hs_m) if env else []

    def envelope_note(self, legs: list[dict], draft_m: float) -> str | None:
        """For a network: how many of a plan's legs (rpm, wind_kn, hs_m each) sail outside the conditions it was fitted
        on, the farthest, and that the physical form fitted on the same rows takes over there; None when all lie
        inside, and for the other forms (they extrapolate as fitted)."""
        if self.form != "mlp":
            return None
        worst: dict[str, tuple[float, str]] = {}  # per input: (how far outside, 'hs_m 8 > 5.2') of the farthest leg
        n = 0
        for leg in legs:
            out = self.outside_envelope(leg["rpm"], draft_m, leg.get("wind_kn", 0.0), leg.get("hs_m", 0.0))
            n += bool(out)
            for item in out:
                name, v, _, edge = item.split(" ")
                far = abs(float(v) - float(edge))
                if far > worst.get(name, (-1.0, ""))[0]:
                    worst[name] = (far, item)
        if not n:
            return None
        return (f"{n} of {len(legs)} legs outside the conditions network model v{self.version} was fitted on "
                f"({', '.join(item for _, item in worst.values())}): speed and fuel follow the physical form fitted on the "
                "same reports there")

    def clip_rpm_options(self, rpm_options, voyage: str = "") -> tuple[tuple[float, ...], str | None]:
        """(allowed rpm settings within the rpm range the model was fitted on, why some were clipped or None).

        A setting more than RPM_SLACK of the range's top outside it becomes its nearest end (duplicates merged):
        no model is trusted far beyond the engine speeds it saw, and a data-driven one extrapolates badly there.
        Within the slack a setting is kept: reports sampled up to 99.9 rpm say nothing against 100."""
        from pipeline.performance.sanity import Envelope

        opts = tuple(sorted(float(r) for r in rpm_options))
        env = Envelope.from_json(self.envelope)
        if env is None or not opts:
            return opts, None
        lo, hi = env.rpm
        slack = RPM_SLACK * hi
        out = [r for r in opts if not (lo - slack <= r <= hi + slack)]
        if not out:
            return opts, None
        clipped = tuple(sorted({r if lo - slack <= r <= hi + slack else min(max(r, lo), hi) for r in opts}))
        note = (f"{voyage + ': ' if voyage else ''}rpm settings {', '.join(f'{r:g}' for r in out)} outside the "
                f"{lo:g}–{hi:g} rpm the vessel's model v{self.version} was fitted on: clipped to {', '.join(f'{r:g}' for r in clipped)}")
        return clipped, note


RPM_SLACK = 0.02  # share of the fitted rpm range's top within which a voyage's setting is not clipped


def model_from_stored(stored: dict | None, imo: int | None = None) -> PerformanceModel | None:
    """The model of a stored active model (`fleet_store.active_models` values), or None if there is none or its
    coefficients are not those of its form as defined now (a model stored before a form changed: refit it)."""
    if not stored or "speed" not in stored or "fuel" not in stored or stored.get("form") not in features.FORM_IDS:
        return None
    fid = features.FORM_IDS[stored["form"]]
    if tuple(stored["speed"]) != features.SPEED_REGRESSORS[fid] or tuple(stored["fuel"]) != features.FUEL_REGRESSORS[fid]:
        return None
    return PerformanceModel(form=stored["form"], speed_coef=np.array(list(stored["speed"].values()), dtype=np.float64),
                            fuel_coef=np.array(list(stored["fuel"].values()), dtype=np.float64),
                            months_dd=float(stored.get("months_dd") or 0.0), imo=None if imo is None else int(imo),
                            version=stored.get("version"), envelope=_envelope(stored.get("envelope")),
                            data_to_utc=None if stored.get("data_to_utc") is None
                            else str(np.datetime64(stored["data_to_utc"], "s")))


def unusable_reason(stored: dict | None, imo: int) -> str | None:
    """Why the stored model `stored` of vessel `imo` cannot be used (its coefficients are not those of its form as
    defined now, e.g. a network stored before it carried its physical fallback), naming what to run; None when it
    can be used or there is none."""
    if not stored or model_from_stored(stored, imo) is not None:
        return None
    form = stored.get("form")
    fid = features.FORM_IDS.get(form)
    have = len(stored.get("speed") or ()), len(stored.get("fuel") or ())
    want = (features.N_SPEED[fid], features.N_FUEL[fid]) if fid is not None else None
    what = (f"{have[0]} speed and {have[1]} fuel coefficients where the {form} form now has {want[0]} and {want[1]}"
            if want else f"an unknown form {form!r}")
    return (f"vessel {imo}: model v{stored.get('version')} ({form}) was stored by an older definition of its form "
            f"({what}); run `jitroute refit --imo {imo}`")


def _envelope(text) -> dict | None:
    if not text:
        return None
    return json.loads(text) if isinstance(text, str) else dict(text)


def reference_model(design_speed_kn: float = 14.0, rpm_max: float = 100.0, design_fuel_tph: float = 1.5) -> PerformanceModel:
    """A plausible physical-form model from design data, for vessels without a fit and for tests.

    STW ≈ design speed at max rpm in calm water, proportional to rpm; fuel ∝ rpm³. Head wind
    costs ~1 kn at 30 kn wind, head seas ~1.5 kn at 4 m (less from the beam, least following).
    """
    a_rpm = design_speed_kn / rpm_max
    speed = np.array([0.0, a_rpm, 0.0, 0.0, 1.0 / 900.0, 1.5 / 16.0, 0.0])
    r3max = (rpm_max / 100.0) ** 3
    fuel = np.array([0.0, design_fuel_tph / r3max, 0.0, 0.0, 0.0002, 0.01])
    return PerformanceModel(form="physical", speed_coef=speed, fuel_coef=fuel)
