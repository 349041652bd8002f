"""Sample camera paths of the BVE in the synthetic world, like the paper's Fig. 4.

    python examples/sample_paths.py [OUT_DIR]

Writes OUT_DIR/sample_paths.png (default OUT_DIR: out/, which git ignores; needs the plots
extra: pip install -e ".[plots]").
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bve_mj import EXPERIMENTS, Belief, Settings, SyntheticWorld, make_planner, run_episode
from bve_mj.cli.script import ScriptParser, folder, guarded
from bve_mj.config import with_overrides
from bve_mj.loop.synthetic import sample_scenario
from bve_mj.reporting.plots import plot_sample_paths


def main(out_dir: str = "out") -> None:
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    out = Path(out_dir) / "sample_paths.png"
    panels = []
    for name, measurement, model, run in (
        ("E2", "range", "paper", 3),
        ("E2", "range", "consistent", 3),
        ("E4", "camera", "paper", 5),
        ("E9", "range", "consistent", 5),
    ):
        s = with_overrides(Settings(), measurement={"kind": measurement}, planner={"planning_model": model})
        e = EXPERIMENTS[name]
        scenario_ss, noise_ss, planner_ss = np.random.SeedSequence(0, spawn_key=(run,)).spawn(3)
        scenario = sample_scenario(s.protocol, np.random.default_rng(scenario_ss))
        world = SyntheticWorld(s.measurement.kind, s.sigma_c_m2(), scenario, np.random.default_rng(noise_ss))
        planner = make_planner(s, e.loss, e.constraints, np.random.default_rng(planner_ss))
        prior = Belief.isotropic(scenario.initial_estimate, s.filter.initial_sigma_m)
        result = run_episode(world, planner, prior, s.filter, s.protocol.steps)
        title = f"{name} ({e.loss}), {measurement} measurement, {model} planning model"
        panels.append((title, result, scenario.p_world_fruit))
    c = Settings().constraints
    workspace = (np.array(c.workspace_centre_m), c.workspace_radius_m)
    print(f"wrote {plot_sample_paths(panels, out, workspace=workspace)}")


if __name__ == "__main__":
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir", nargs="?", type=folder, default="out")
    guarded(lambda: main(ap.parse_args().out_dir))
