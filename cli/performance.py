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
    t.add_column("why")
    for s in summaries:
        t.add_row(str(s["imo"]), str(s["n"]), s.get("form", "-"), _fmt(s.get("speed_r2")), _fmt(s.get("speed_rmse")),
                  _fmt(s.get("speed_holdout_rmse")), _fmt(s.get("fuel_r2")), _fmt(s.get("fuel_rmse"), 4),
                  _fmt(s.get("fuel_holdout_rmse"), 4), "[green]yes" if s["changed"] else "[yellow]no",
                  s.get("flag") or s.get("why") or s.get("reason", ""))
    return t


def register(app: typer.Typer) -> None:
    noon = typer.Typer(help="Noon reports: import with validation.", no_args_is_help=True)
    fleet = typer.Typer(help="Fleet data: vessels, voyages, demo generator.", no_args_is_help=True)
    app.add_typer(noon, name="noon")
    app.add_typer(fleet, name="fleet")

    @noon.command("import")
    def noon_import(file: Path = typer.Argument(..., help="CSV or Parquet of noon reports (one or many vessels)."),
                    data: Optional[Path] = DataOpt):
        """Validate and import noon reports; bad rows go to noon_reports_rejected with a reason."""
        from flows.jobs.refit import import_noon_file

        c = run_job("flows.refit", "import_noon_reports", import_noon_file, path=str(file),
                    data_root=str(data) if data else None)
        console.print(f"{file}: {c['rows']} rows → {c['inserted']} imported, {c['already_present']} already present, "
                      f"{c['rejected']} rejected")
        if c["reasons"] or c["conflicts"]:
            t = Table(title="Rejected rows by reason")
            t.add_column("reason")
            t.add_column("rows", justify="right")
            for reason, n in sorted(c["reasons"].items(), key=lambda kv: -kv[1]):
                t.add_row(reason, str(n))
            if c["conflicts"]:
                t.add_row("conflicts with a stored report", str(c["conflicts"]))
            console.print(t)

    @app.command()
    def refit(imo: Optional[list[int]] = typer.Option(None, "--imo", help="Vessel(s) to refit; default all."),
              form: str = typer.Option("best", help="Model form: best (default: every form scored on the newest "
                                                    "reports, the best proposed), physical, thesis or mlp."),
              data: Optional[Path] = DataOpt):
        """Refit vessels' speed and fuel models from their noon reports; prints fit quality and changes."""
        from flows.jobs.refit import refit_job
        from pipeline.performance.refit import check_form

        try:
            check_form(form)  # before anything is read
        except ValueError as exc:
            fail(str(exc))

        summaries = run_job("flows.refit", "refit_performance", refit_job, imos=imo or None,
                            data_root=str(data) if data else None, form=form)
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
            noon_import(folder / "noon_reports.csv", data)
