"""A small campaign from Python: BVE against the circle baseline in both worlds, resumable.

python examples/campaign.py [OUT_DIR] [RUNS]   (defaults: out/campaign_example/, which git
ignores, and 5 runs per cell; run it twice: the second call finds every run done and only
rewrites the outputs)

The same from the shell:
bve-mj campaign --out out/campaign_example --experiments E1,E5 --worlds synthetic,mujoco \
    --planners bve,circle --measurements camera --runs 5
"""

from __future__ import annotations

from bve_mj import Settings
from bve_mj.campaigns.runner import run_campaign
from bve_mj.campaigns.spec import CampaignSpec
from bve_mj.cli.script import ScriptParser, folder, guarded, integer
from bve_mj.reporting.campaign_report import format_cells, write_campaign_outputs


def main(out: str = "out/campaign_example", runs: int = 5) -> None:
    spec = CampaignSpec(
        experiments=("E1", "E5"),
        worlds=("synthetic", "mujoco"),
        planners=("bve", "circle"),
        measurements=("camera",),
        runs=runs,
        seed=0,
    )

    def progress(done: int, total: int) -> None:
        print(f"\r{done}/{total} runs", end="")

    result = run_campaign(Settings(), spec, out, workers=2, progress=progress)
    print(f"\n{result.computed_runs} runs computed, {result.resumed_runs} found done")
    for line in format_cells(result):
        print(line)
    for path in write_campaign_outputs(result):
        print(f"wrote {path}")


if __name__ == "__main__":
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", type=folder, default="out/campaign_example")
    ap.add_argument("runs", nargs="?", type=integer(1), default=5)
    args = ap.parse_args()
    guarded(lambda: main(args.out, args.runs))
