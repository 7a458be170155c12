"""Prefect flows `refit-performance`, `import-fleet`, `import-noon-reports` and `import-bunker-logs`; the work is in
flows/jobs/refit.py."""

from __future__ import annotations

from prefect import flow

from flows.jobs.refit import DEFAULT_FORM, import_bunker_file, import_fleet_folder, import_noon_file, refit_job
from flows.runner import InPrefect, register_flow
from flows.settings import refuse_served_overrides, served_input_file


@register_flow
@flow(name="import-noon-reports")
def import_noon_reports(path: str, data_root: str | None = None, replace: bool = False) -> dict:
    """Validate a noon-report file and store good rows; bad rows go to noon_reports_rejected with a reason."""
    refuse_served_overrides(data_root=data_root)
    path = served_input_file("path", path)
    return import_noon_file(path, data_root=data_root, replace=replace, run=InPrefect())


@register_flow
@flow(name="import-fleet")
def import_fleet(folder: str, data_root: str | None = None) -> dict:
    """Validate and store vessels.csv and voyages.csv of a folder; refused rows go to *_rejected with their reason."""
    refuse_served_overrides(data_root=data_root)
    folder = served_input_file("folder", folder)
    return import_fleet_folder(folder, data_root=data_root, run=InPrefect())


@register_flow
@flow(name="import-bunker-logs")
def import_bunker_logs(path: str, data_root: str | None = None) -> dict:
    """Validate a bunker-log file and store good rows; rejected and conflicting rows are returned with a reason."""
    refuse_served_overrides(data_root=data_root)
    path = served_input_file("path", path)
    return import_bunker_file(path, data_root=data_root, run=InPrefect())


@register_flow
@flow(name="refit-performance")
def refit_performance(imos: list[int] | None = None, data_root: str | None = None, form: str = DEFAULT_FORM,
                      robust: bool | None = None, gate: list[str] | None = None) -> list[dict]:
    """Refit every (or the given) vessel's speed and fuel model; activation only for a model that is not worse."""
    refuse_served_overrides(data_root=data_root)
    return refit_job(imos, data_root=data_root, form=form, robust=robust, gate=gate, run=InPrefect())
