"""Where a voyage's export files go: always inside the run folder, whatever the voyage ID says, and in the voyage's
own folder `voyages/<voyage_id>/`, so a voyage named like a run file (`fleet_map`, `weather_waves_<cycle>`) or
like another voyage's file (`V1.convergence` against V1's `.convergence.png`) overwrites nothing."""

from __future__ import annotations

from pathlib import Path

from pipeline.validate_ids import InvalidIdentifier, check_voyage_id


class ExportPathError(InvalidIdentifier):
    """A voyage's export file would land outside its run folder (or the voyage ID is unusable)."""


def export_name(voyage_id: str, suffix: str) -> str:
    """`voyage_id + suffix` as one plain file name, refused (ExportPathError naming the voyage) unless the voyage
    ID is a plain name (`pipeline.validate_ids.VOYAGE_ID_PATTERN`).

    `suffix` is the file ending, e.g. ".rtz" or "_plan.png"; it must not contain a path separator either.
    """
    try:
        vid = check_voyage_id(voyage_id)
    except InvalidIdentifier as exc:
        raise ExportPathError(f"{exc}: its export files are not written") from exc
    if "/" in suffix or "\\" in suffix or "\x00" in suffix or ".." in suffix:
        raise ExportPathError(f"voyage {vid}: export suffix {suffix!r} is not a plain file ending")
    return f"{vid}{suffix}"


VOYAGES_FOLDER = "voyages"


def voyage_export_key(voyage_id: str, suffix: str) -> str:
    """`voyages/<voyage_id>/<voyage_id><suffix>`: the key of a voyage's export file in its run folder."""
    name = export_name(voyage_id, suffix)
    return f"{VOYAGES_FOLDER}/{name[: len(name) - len(suffix)]}/{name}"


def export_path(run_dir: Path, voyage_id: str, suffix: str) -> Path:
    """`run_dir / export_name(voyage_id, suffix)`, refused unless the resolved file lies directly in `run_dir`."""
    name = export_name(voyage_id, suffix)
    vid = name[: len(name) - len(suffix)]
    base = Path(run_dir).resolve()
    target = (base / name).resolve()
    if target.parent != base:
        raise ExportPathError(f"voyage {vid}: export file {target} would be outside the run folder {base}; not written")
    return target
