"""Run 52North WeatherRoutingTool on one config and time its routing: run by bench/peer_wrt.py with WRT's own
interpreter (never jitroute's), with WRT's source on PYTHONPATH.

    /tmp/wrt-venv/bin/python bench/peer_wrt_run.py CONFIG.json CPU.json

The config's `longitude_shift_deg` (not a WRT setting; removed before WRT validates the config) is the frame the
voyage was handed over in (bench/peer_wrt_io.py): global_land_mask's lookups are turned back by it, so WRT meets the
real land. Writes {"cpu_s": process CPU time of the routing call (weather, ship, constraints and the isofuel search,
after the imports), "wall_s"} to CPU.json; WRT itself writes the route into the config's ROUTE_PATH.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path


def land_in_frame(shift_deg: float) -> None:
    """global_land_mask answers for the real longitude of a point given in the frame turned `shift_deg` east."""
    if not shift_deg:
        return
    from global_land_mask import globe

    real_is_land = globe.is_land

    def is_land(lat, lon):
        import numpy as np

        return real_is_land(lat, (np.asarray(lon) + shift_deg + 180.0) % 360.0 - 180.0)

    globe.is_land = is_land


def main() -> int:
    cfg_path, cpu_path = Path(sys.argv[1]), Path(sys.argv[2])
    cfg = json.loads(cfg_path.read_text())
    shift = float(cfg.pop("longitude_shift_deg", 0.0))
    from WeatherRoutingTool.config import Config, set_up_logging
    from WeatherRoutingTool.execute_routing import execute_routing
    from WeatherRoutingTool.ship.ship_config import ShipConfig

    set_up_logging()
    land_in_frame(shift)
    config = Config.assign_config(init_mode="from_dict", config_dict=cfg)
    ship_config = ShipConfig.assign_config(init_mode="from_dict", config_dict=cfg)
    c0, w0 = time.process_time(), time.perf_counter()
    execute_routing(config, ship_config)
    cpu_s, wall_s = time.process_time() - c0, time.perf_counter() - w0
    cpu_path.write_text(json.dumps({"cpu_s": cpu_s, "wall_s": wall_s}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
