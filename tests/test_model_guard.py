"""A network outside the conditions it was trained on follows the physical form fitted on the same reports (not
a clamp), plans say so, and a network stored by an older definition is refused with what to run."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pipeline.performance import features, mlp
from pipeline.performance.model import PerformanceModel, model_from_stored, unusable_reason
from pipeline.performance.refit import refit_vessel
from tests.test_performance import _nonlinear_report_frame


def _network():
    reports = _nonlinear_report_frame()
    rows, s = refit_vessel(9140607, reports, None, 1, form="mlp")
    coef = np.array(list(json.loads(rows[0]["coefficients"]).values()))
    return rows, s, PerformanceModel("mlp", coef, coef, imo=9140607, version=1, envelope=json.loads(rows[0]["envelope"]))


def _linear(coef, target, rpm, hs):
    """The physical form's linear terms (no caps) at rpm, draft 10 m, trim 0.5 m, calm wind and head seas hs."""
    row = features.design_matrix(features.FORM_PHYSICAL, target, np.array([rpm]), np.array([10.0]), np.array([0.5]),
                                 np.zeros(1), np.zeros(1), np.array([hs]), np.zeros(1), np.zeros(1))
    return float(row[0] @ coef)


def test_a_network_follows_its_physical_form_at_higher_rpm_and_in_heavier_seas_than_it_saw():
    rows, s, m = _network()
    assert s["changed"] and s["form"] == "mlp"  # it passed the sanity gate, fallback included
    p = m.speed_coef
    lo, hi = mlp.input_bounds(p)
    rpm_hi, hs_hi = hi[0], hi[4]  # head seas: waves·w = Hs
    assert 8.0 > hs_hi  # the largest seas seen from ahead: 7.2 m
    phys_s, phys_f = p[mlp.PHYSICAL_SPEED], p[mlp.PHYSICAL_FUEL]
    assert phys_s[1] > 0 and phys_f[1] > 0  # the physical form fitted on the same rows came with it

    def at(rpm, hs):
        return float(m.stw_kn(rpm, 10.0, 0.5, 0.0, 0.0, hs, 0.0)), float(m.fuel_tph(rpm, 10.0, 0.5, 0.0, 0.0, hs, 0.0))

    edge, far = at(rpm_hi, hs_hi), at(1.2 * rpm_hi, 8.0)
    # beyond the edge it changes as the physical form does (its linear terms), from the network's value at the edge
    assert far[0] - edge[0] == pytest.approx(_linear(phys_s, "speed", 1.2 * rpm_hi, 8.0) - _linear(phys_s, "speed", rpm_hi, hs_hi),
                                             rel=1e-9)
    assert far[1] - edge[1] == pytest.approx(_linear(phys_f, "fuel", 1.2 * rpm_hi, 8.0) - _linear(phys_f, "fuel", rpm_hi, hs_hi),
                                             rel=1e-9)
    # a clamp would answer as at the edge: 8 m head seas as fast as the largest seas seen, 1.2 × rpm for the same fuel
    clamped = mlp.forward(p, features.mlp_inputs(1.2 * rpm_hi, 10.0, 0.5, 0.0, 0.0, 8.0, 0.0))[0]
    np.testing.assert_allclose(clamped, edge, rtol=1e-9)
    assert at(1.2 * rpm_hi, 8.0)[0] < at(1.2 * rpm_hi, hs_hi)[0] - 0.5  # heavier head seas cost speed
    assert far[1] > at(rpm_hi, 8.0)[1] * 1.3  # more rpm costs fuel (rpm³: 1.2³ = 1.73)
    # inside its envelope the network is unchanged
    mid = (lo + hi) / 2
    inside = float(m.stw_kn(mid[0], mid[1], mid[2], mid[3], 0.0, mid[4], 0.0))
    assert inside == pytest.approx(float(mlp.forward(p, mid[None, :])[0, 0]), rel=1e-12)
    # a plan sailing there says so
    legs = [{"rpm": rpm_hi * 0.9, "wind_kn": 0.0, "hs_m": 1.0}, {"rpm": rpm_hi * 0.9, "wind_kn": 0.0, "hs_m": 12.0}]
    note = m.envelope_note(legs, 10.0)
    assert note.startswith("1 of 2 legs outside the conditions network model v1 was fitted on (hs_m 12 > ")
    assert "follow the physical form" in note and m.envelope_note(legs[:1], 10.0) is None


def test_a_network_stored_before_it_carried_its_physical_form_is_refused_with_what_to_run():
    from pipeline.routing.job import RouteJob, RoutingInputError, routing_problem

    old = {"form": "mlp", "version": 3, "speed": {f"p{i:03d}": 0.1 for i in range(266)},
           "fuel": {f"p{i:03d}": 0.1 for i in range(266)}}
    assert model_from_stored(old, 9140607) is None
    why = unusable_reason(old, 9140607)
    assert why == ("vessel 9140607: model v3 (mlp) was stored by an older definition of its form (266 speed and 266 fuel "
                   "coefficients where the mlp form now has 279 and 279); run `jitroute refit --imo 9140607`")
    assert unusable_reason(None, 9140607) is None
    job = RouteJob(voyage={"voyage_id": "V1", "imo": 9140607}, vessel={}, model=None, run_id="r", cycle=None, model_note=why)
    with pytest.raises(RoutingInputError, match=r"^voyage V1: vessel 9140607: model v3 \(mlp\) .* run `jitroute refit --imo 9140607`$"):
        routing_problem(job)
