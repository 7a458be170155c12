"""`jitroute noon import`, `jitroute refit`, `jitroute bunker import`, `jitroute model fuzzy`, `jitroute fleet generate|import`."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from cli.console import console, fail
from cli.launch import run_job
DataOpt = typer.Option(None, "--data", help="Data root (default ./data or $JITROUTE_DATA).")


def _fmt(x, nd=3):
    return "-" if x is None or x != x else f"{x:.{nd}f}"


def refit_table(summaries: list[dict]) -> Table:
    t = Table(title="Performance models")
    for col in ("IMO", "n", "form", "STW R²", "STW RMSE kn", "STW held-out", "fuel R²", "fuel RMSE t/h", "fuel held-out", "changed"):
        t.add_column(col, no_wrap=True, justify="right" if col not in ("changed", "form") else "left")
    t.add_column("gate")
    t.add_column("why")
    for s in summaries:
        t.add_row(str(s["imo"]), str(s["n"]), s.get("form", "-"), _fmt(s.get("speed_r2")), _fmt(s.get("speed_rmse")),
                  _fmt(s.get("speed_holdout_rmse")), _fmt(s.get("fuel_r2")), _fmt(s.get("fuel_rmse"), 4),
                  _fmt(s.get("fuel_holdout_rmse"), 4), "[green]yes" if s["changed"] else "[yellow]no",
                  s.get("gate", "-"), s.get("flag") or s.get("why") or s.get("reason", ""))
    return t


def _json_safe(v):
    """`v` with every non-finite float (in dicts and lists too) made None, as strict JSON requires."""
    from pipeline.export.geojson import json_value

    if isinstance(v, dict):
        return {k: _json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_safe(x) for x in v]
    return json_value(v)


def register(app: typer.Typer) -> None:
    noon = typer.Typer(help="Noon reports: import with validation.", no_args_is_help=True)
    fleet = typer.Typer(help="Fleet data: vessels, voyages, demo generator.", no_args_is_help=True)
    app.add_typer(noon, name="noon")
    app.add_typer(fleet, name="fleet")

    @noon.command("import")
    def noon_import(file: Path = typer.Argument(..., help="CSV or Parquet of noon reports (one or many vessels)."),
                    replace: bool = typer.Option(False, "--replace", help="Corrected reports: a row differing from the "
                                                 "stored report of the same vessel and time replaces it (the old one is "
                                                 "kept in noon_reports_history) instead of being refused."),
                    data: Optional[Path] = DataOpt):
        """Validate and import noon reports; bad rows go to noon_reports_rejected with a reason."""
        from flows.jobs.noon_import import import_noon_file

        kw = {"replace": True} if replace else {}
        c = run_job("flows.refit", "import_noon_reports", import_noon_file, path=str(file),
                    data_root=str(data) if data else None, **kw)
        console.print(f"{file}: {c['rows']} rows → {c['inserted']} imported, {c['already_present']} already present, "
                      + (f"{c['replaced']} replaced (old ones in noon_reports_history), " if c.get("replaced") else "")
                      + (f"{c['excluded']} excluded earlier (kept out: `noon exclude`), " if c.get("excluded") else "")
                      + f"{c['rejected']} rejected")
        if c["reasons"] or c["conflicts"]:
            t = Table(title="Rejected rows by reason")
            t.add_column("reason")
            t.add_column("rows", justify="right")
            for reason, n in sorted(c["reasons"].items(), key=lambda kv: -kv[1]):
                t.add_row(reason, str(n))
            if c["conflicts"]:
                t.add_row("conflicts with a stored report (corrected reports: import with --replace)", str(c["conflicts"]))
            console.print(t)

    @noon.command("exclude")
    def noon_exclude(imo: int = typer.Option(..., "--imo", help="Vessel IMO number."),
                     from_: str = typer.Option(..., "--from", help="First report time to exclude (UTC, e.g. 2021-03-01T00)."),
                     to: str = typer.Option(..., "--to", help="Last report time to exclude (UTC), inclusive."),
                     reason: str = typer.Option(..., "--reason", help="Why (kept with the reports), e.g. 'speed log broken'."),
                     data: Optional[Path] = DataOpt):
        """Take a vessel's reports of a period out of the refit (e.g. a broken speed log); they are kept in
        noon_reports_history with the reason."""
        import re

        from flows.jobs.refit import UnknownVesselError, exclude_noon_period
        from pipeline.timestamps import parse_iso_utc

        times = []
        for opt, text in (("--from", from_), ("--to", to)):  # ISO 8601 only: 01/06/2020 is refused, never guessed
            hour_only = re.fullmatch(r"\d{4}-\d{2}-\d{2}T\d{2}", text.strip())  # 2021-03-01T00, as the help says
            t, why = parse_iso_utc(text.strip() + (":00" if hour_only else ""))
            if t is None:
                fail(f"{opt} {text!r}: {why}; use ISO 8601 (UTC unless an offset is given), e.g. 2021-03-01 or "
                     "2021-03-01T00:00")
            times.append(t)
        t0, t1 = times
        if t1 < t0:
            fail(f"--to {to} is before --from {from_}")
        if not reason.strip():
            fail("--reason must say why the reports are excluded")
        from pipeline.validate_ids import name_problem

        if name_problem(reason):  # kept with the reports, shown in logs and tables
            fail(f"--reason: {name_problem(reason)}; give plain text")
        try:
            n = exclude_noon_period(imo, str(t0), str(t1), reason.strip(), data_root=str(data) if data else None)
        except UnknownVesselError as exc:
            fail(str(exc))
        console.print(f"vessel {imo}: {n} reports from {t0} to {t1} excluded ({reason.strip()}); kept in noon_reports_history. "
                      "Run `jitroute refit` to refit without them.", highlight=False)

    @app.command()
    def refit(imo: Optional[list[int]] = typer.Option(None, "--imo", help="Vessel(s) to refit; default all."),
              form: str = typer.Option("physical", help="Model form: physical (default), thesis, mlp, or best (opt-in: "
                                                        "every form scored on the newest reports, the physical one "
                                                        "kept unless another is significantly better; trains the "
                                                        "network where it could win, many times the CPU)."),
              gate: Optional[list[str]] = typer.Option(None, "--gate", metavar="NAME=VALUE",
                                                       help="Override a gate setting for this refit (repeatable), e.g. "
                                                            "min_rows_per_coef=3, min_r2=0.1, sanity=false; the table's "
                                                            "gate column and perf_models.gate say which gate applied."),
              data: Optional[Path] = DataOpt):
        """Refit vessels' speed and fuel models from their noon reports (validated on the newest reports, then fitted
        on all of them); prints fit quality, the gate applied and changes."""
        from flows.jobs.refit import refit_job
        from pipeline.performance.refit import Gate, check_form, gate_with

        try:
            check_form(form)  # before anything is read
            gate_with(Gate(), gate)
        except ValueError as exc:
            fail(str(exc))

        summaries = run_job("flows.refit", "refit_performance", refit_job, imos=imo or None,
                            data_root=str(data) if data else None, form=form, gate=gate or None)
        console.print(refit_table(summaries))

    bunker = typer.Typer(help="Bunker logs: import with validation.", no_args_is_help=True)
    app.add_typer(bunker, name="bunker")

    @bunker.command("import")
    def bunker_import(file: Path = typer.Argument(..., help="CSV or Parquet: imo, bill_no, date_utc, port, supplier, fuel_type, "
                                                            "received_t, rob_t."),
                      data: Optional[Path] = DataOpt):
        """Validate and import bunker logs; rejected rows are listed with a reason."""
        from flows.jobs.refit import import_bunker_file

        c = run_job("flows.refit", "import_bunker_logs", import_bunker_file, path=str(file),
                    data_root=str(data) if data else None)
        console.print(f"{file}: {c['rows']} rows → {c['inserted']} imported, {c['already_present']} already present, "
                      f"{c['rejected']} rejected")
        for reason, n in sorted(c["reasons"].items(), key=lambda kv: -kv[1]):
            console.print(f"  {n} × {reason}", highlight=False, markup=False)
        if c["reasons"]:
            console.print("  refused rows, with their reason and raw text: table bunker_logs_rejected")
        for key in c["conflicts"]:
            console.print(f"  conflicts with the stored row: {key} (delete it first to correct it)")

    model = typer.Typer(help="Performance models: quick evaluations.", no_args_is_help=True)
    app.add_typer(model, name="model")

    @model.command("fuzzy")
    def model_fuzzy(speed: float = typer.Argument(..., help="Ship speed, m/s (5–11)."),
                    resistance: float = typer.Argument(..., help="Resistance, ×10⁴ N (0–6)."),
                    wave: float = typer.Argument(..., help="Significant wave height, m (0–8).")):
        """Fuel rate of the 27-rule Mamdani fuzzy model (the Greek fuzzy fuel-consumption work)."""
        from pipeline.performance import fuzzy

        for name, value, (lo, hi) in (("SPEED", speed, fuzzy.SPEED_RANGE), ("RESISTANCE", resistance, fuzzy.RESISTANCE_RANGE),
                                      ("WAVE", wave, fuzzy.WAVE_RANGE)):
            if not lo <= value <= hi:
                fail(f"{name} {value:g} is outside the model's range {lo:g}–{hi:g}")
        rate = fuzzy.fuel_tph(speed, resistance, wave)
        rules = ", ".join(map(str, fuzzy.fired_rules(speed, resistance, wave)))
        console.print(f"fuel {rate:.3f} t/h (rules fired: {rules})")

    @model.command("predict")
    def model_predict(imo: int = typer.Option(..., "--imo", help="Vessel IMO number."),
                      rpm: float = typer.Option(..., "--rpm", help="Engine speed, rpm."),
                      wind_kn: float = typer.Option(0.0, "--wind-kn", help="True wind speed, kn."),
                      wind_dir_rel: float = typer.Option(0.0, "--wind-dir-rel", help="Wind coming from, relative to the bow, "
                                                                                      "degrees (0 head, 180 following; −180..360)."),
                      hs_m: float = typer.Option(0.0, "--hs-m", help="Significant wave height, m."),
                      wave_dir_rel: float = typer.Option(0.0, "--wave-dir-rel", help="Waves coming from, relative to the bow, degrees."),
                      draft_m: Optional[float] = typer.Option(None, "--draft-m", help="Mean draft, m (default: the middle of "
                                                                                      "the drafts the model was fitted on)."),
                      trim_m: Optional[float] = typer.Option(None, "--trim-m", help="Trim, m (default: as fitted)."),
                      version: Optional[int] = typer.Option(None, "--version", help="Model version (default: the active one)."),
                      as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
                      data: Optional[Path] = DataOpt):
        """Speed through water and fuel rate of a vessel's model for given conditions, flagged when they lie outside
        the conditions the model was fitted on."""
        import json
        import math

        from flows.settings import load_settings
        from pipeline.performance.model import model_from_stored, unusable_reason
        from storage import fleet_store

        for name, v in (("--rpm", rpm), ("--wind-kn", wind_kn), ("--hs-m", hs_m), ("--draft-m", draft_m), ("--trim-m", trim_m),
                        ("--wind-dir-rel", wind_dir_rel), ("--wave-dir-rel", wave_dir_rel)):
            if v is not None and not math.isfinite(v):
                fail(f"{name} {v} is not a finite number")
        if rpm <= 0 or wind_kn < 0 or hs_m < 0 or (draft_m is not None and draft_m <= 0):
            fail("--rpm and --draft-m must be positive, --wind-kn and --hs-m not negative")
        s = load_settings(data_root=data)
        db = s.layout.warehouse
        if not db.exists():
            fail(f"no warehouse at {db}: import the fleet and run `jitroute refit` first")
        stored = fleet_store.model_version(db, imo, version)
        if stored is None:
            fail(f"vessel {imo} has no {'model v' + str(version) if version else 'active model'} in {db}; "
                 "run `jitroute refit` (perf_models lists the versions)")
        m = model_from_stored(stored, imo)
        if m is None:
            fail(unusable_reason(stored, imo) or f"vessel {imo}'s stored model cannot be used; run `jitroute refit`")
        env = m.envelope or {}
        draft = draft_m if draft_m is not None else (sum(env["draft_m"]) / 2 if env.get("draft_m") else 10.0)
        trim = trim_m if trim_m is not None else float(env.get("trim_m", 0.0))
        stw = float(m.stw_kn(rpm, draft, trim, wind_kn, wind_dir_rel, hs_m, wave_dir_rel))
        fuel = float(m.fuel_tph(rpm, draft, trim, wind_kn, wind_dir_rel, hs_m, wave_dir_rel))
        outside = m.outside_envelope(rpm, draft, wind_kn, hs_m)
        out = {"imo": imo, "version": m.version, "form": m.form, "status": stored.get("status", "active"), "rpm": rpm,
               "draft_m": draft, "trim_m": trim, "wind_kn": wind_kn, "wind_dir_rel_deg": wind_dir_rel, "hs_m": hs_m,
               "wave_dir_rel_deg": wave_dir_rel, "months_dd": m.months_dd, "stw_kn": stw, "fuel_tph": fuel,
               "out_of_envelope": bool(outside), "outside": outside, "envelope": m.envelope}
        # far outside its envelope a model's value can overflow: JSON has no Infinity, so null and the reason
        unusable = {k: f"the model gives {out[k]} at these conditions (far outside those it was fitted on)"
                    for k in ("stw_kn", "fuel_tph") if not math.isfinite(out[k])}
        if as_json:
            out = {**out, **{k: None for k in unusable}, "not_finite": unusable}
            print(json.dumps(_json_safe(out), allow_nan=False))
            return
        console.print(f"vessel {imo} model v{m.version} ({m.form}, {out['status']}): STW {stw:.2f} kn, fuel {fuel:.3f} t/h "
                      f"at {rpm:g} rpm, draft {draft:.2f} m", highlight=False)
        for k, why in unusable.items():
            console.print(f"[yellow]{k}:[/] {why}", highlight=False)
        if outside:
            console.print(f"[yellow]outside the conditions the model was fitted on:[/] {', '.join(outside)}", highlight=False)

    @fleet.command("generate")
    def fleet_generate(out: Path = typer.Option(..., "--out"), start: str = typer.Option("2020-12-01T00", help="Reports end and voyages start here (UTC)."),
                       vessels: int = typer.Option(12, help="Number of vessels."), seed: int = typer.Option(7)):
        """Write a deterministic demo fleet: vessels.csv, noon_reports.csv, voyages.csv."""
        from pipeline.synthetic.fleet import generate_fleet, write_fleet

        paths = write_fleet(generate_fleet(start, n_vessels=vessels, seed=seed), out)
        for k, p in paths.items():
            console.print(f"{k}: {p}")

    @fleet.command("import")
    def fleet_import(folder: Path = typer.Argument(..., help="Folder with vessels.csv, voyages.csv and optionally noon_reports.csv."),
                     data: Optional[Path] = DataOpt):
        """Import vessels and voyages (validated; refused rows are kept with a reason) and noon reports from a folder."""
        from flows.jobs.refit import import_fleet_folder

        c = run_job("flows.refit", "import_fleet", import_fleet_folder, folder=str(folder),
                    data_root=str(data) if data else None)
        n_rej = {k: sum(c[f"{k}_rejected"].values()) for k in ("vessels", "voyages")}
        console.print(f"{c['vessels']} vessels, {c['voyages']} voyages imported; "
                      f"{n_rej['vessels']} vessel rows and {n_rej['voyages']} voyage rows refused")
        if n_rej["vessels"] or n_rej["voyages"]:
            t = Table(title="Refused rows by reason (tables vessels_rejected, voyages_rejected)")
            for col in ("file", "reason", "rows"):
                t.add_column(col)
            for k in ("vessels", "voyages"):
                for reason, n in sorted(c[f"{k}_rejected"].items(), key=lambda kv: -kv[1]):
                    t.add_row(f"{k}.csv", reason, str(n))
            console.print(t)
        if (folder / "noon_reports.csv").exists():
            noon_import(folder / "noon_reports.csv", replace=False, data=data)
