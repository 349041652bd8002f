"""Seeded Monte-Carlo runs and what they measure.

- :mod:`.spec`: a campaign's cells and each run's seed; :mod:`.runs`: one run → its row;
  :mod:`.store`: the SQLite run store; :mod:`.executors`: in-process, spawned pool, Dask;
  :mod:`.runner`: :func:`run_campaign`.
- :mod:`.paper`: the paper's table (E1-E10 in the synthetic world).
- :mod:`.scenarios`: the greenhouse scenario suite; :mod:`.calibration`: the detector's noise
  calibration.
"""

from __future__ import annotations

from bve_mj.campaigns.runner import CampaignResult, run_campaign
from bve_mj.campaigns.spec import WORLDS, CampaignSpec, Cell, cell_settings, episode_seed, parse_grid
from bve_mj.campaigns.store import RunStore

__all__ = [
    "WORLDS",
    "CampaignResult",
    "CampaignSpec",
    "Cell",
    "RunStore",
    "cell_settings",
    "episode_seed",
    "parse_grid",
    "run_campaign",
]
