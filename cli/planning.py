"""`jitroute plan fleet`: assign cargo contracts to vessels and sequence them; the legs become planned voyages."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from cli.console import console
from cli.launch import run_job

plan_app = typer.Typer(help="Fleet operation planning: cargo contracts → vessels → planned voyages.", no_args_is_help=True)


def _money(x) -> str:
    return "-" if x is None else f"{x:,.0f}"


def show_plan(s: dict) -> None:
    t = Table(title=f"Fleet plan {s['plan_id']} as of {s['as_of_utc']} UTC · {s['solve_status']}"
                    + (f" (gap ≤ {100 * s['gap']:.2f} %)" if s.get("gap") else ""))
    for col in ("vessel", "contracts in order", "legs", "fuel (t)", "fuel cost", "days out of service", "cost"):
        t.add_column(col, justify="right" if col not in ("vessel", "contracts in order", "legs") else "left")
    for v in s["vessels"]:
        legs = "\n".join(f"{leg['kind']:7} {leg['from_port']} → {leg['to_port']} {leg['depart_utc'][:16]} → "
                         f"{leg['arrive_utc'][:16]} ({leg['dist_nm']:.0f} NM)" for leg in v["legs"])
        t.add_row(f"{v['name']} {v['imo']}", " → ".join(v["contracts"]), legs, f"{v['fuel_t']:.0f}",
                  _money(v["fuel_cost"]), f"{v['out_of_service_days']:.1f}", _money(v["fuel_cost"] + v["out_of_service_cost"]))
    console.print(t)
    console.print(f"cost: fuel {_money(s['fuel_cost'])} + out of service {_money(s['out_of_service_cost'])} "
                  f"({s['out_of_service_days']:.1f} days) + penalties {_money(s['penalty_cost'])} = {_money(s['total_cost'])}"
                  f" (fuel price {s['fuel_price']:g}/t; planner {s['runtime_s']:.1f} s)")
    if s.get("stopped_by"):
        console.print(f"search: {s['stopped_by']}")
    if s["unassigned"]:
        u = Table(title="Contracts left")
        for col in ("contract", "penalty", "why"):
            u.add_column(col)
        for r in s["unassigned"]:
            u.add_row(str(r["contract_code"]), _money(r["penalty"]), str(r["reason"]))
        console.print(u)
    if s["contracts_refused"]:
        console.print(f"[yellow]{len(s['contracts_refused'])} contract rows refused on import[/] "
                      "(contracts_rejected): " + "; ".join(f"{r['code']}: {r['reason']}" for r in s["contracts_refused"][:10]))
    for r in s.get("committed") or []:
        console.print(f"{r['code']}: {r['reason']}")
    for line in s["no_sea_route"]:
        console.print(f"[yellow]no sea route:[/] {line}")
    console.print(f"voyages: {s['voyages_added']} planned voyages added; {s['voyages_replaced']} unsailed voyages of "
                  f"superseded plans replaced, {s['voyages_kept']} of earlier plans kept (sailed, or of a cargo under way)")
    if s.get("gantt_png"):
        console.print(f"gantt: {s['gantt_png']}")


@plan_app.command("fleet")
def plan_fleet_cmd(contracts: Path = typer.Option(..., "--contracts", help="contracts.csv: code, cargo_type, min_t, max_t, "
                                                  "load_port, discharge_port, early_utc, late_utc[, penalty]."),
                   availability: Optional[Path] = typer.Option(None, "--availability", help="Vessel availability: imo, "
                                                               "from_utc, from_port[, until_utc, until_port, port_hours, "
                                                               "daily_cost, ports, cargo_types, …] (default: as stored)."),
                   ports: Optional[Path] = typer.Option(None, "--ports", help="ports.csv: port, lat, lon of each pilot "
                                                        "station (default: as stored)."),
                   as_of: Optional[str] = typer.Option(None, "--as-of", help="Plan as of this time (ISO 8601 UTC; "
                                                       "default now)."),
                   fuel_price: float = typer.Option(600.0, "--fuel-price", help="Fuel price per tonne."),
                   penalty: float = typer.Option(500_000.0, "--penalty", help="Cost of leaving a contract unassigned "
                                                 "when its row gives none."),
                   effort: float = typer.Option(1.0, "--effort", help="How much search the planner does, counted in "
                                                "work, not time, so the same inputs give the same plan on any machine: "
                                                "1 the default (about a CPU minute on 50 vessels × 200 contracts), "
                                                "0.1 a quick plan, 10 a long search."),
                   time_limit: Optional[float] = typer.Option(None, "--time-limit", help="Optional wall-clock safety "
                                                              "cap, seconds, from building the problem to the plan (default "
                                                              "none); when it stops the search the plan says so, and the "
                                                              "plan then depends on how busy the machine was."),
                   as_json: bool = typer.Option(False, "--json", help="Print the plan as JSON."),
                   data: Optional[Path] = typer.Option(None, "--data", help="Data root (default ./data or $JITROUTE_DATA).")):
    """Assign contracts to vessels and sequence them at least cost; store the plan and its legs as planned voyages."""
    from flows.jobs.planning import plan_fleet_job

    s = run_job("flows.planning", "plan_fleet", plan_fleet_job, contracts=str(contracts),
                availability=str(availability) if availability else None, ports=str(ports) if ports else None,
                as_of=as_of, data_root=str(data) if data else None, fuel_price=fuel_price, penalty=penalty,
                effort=effort, time_limit_s=time_limit)
    if as_json:
        print(json.dumps(s, default=str, indent=1))
    else:
        show_plan(s)


def register(app: typer.Typer) -> None:
    app.add_typer(plan_app, name="plan")
