"""The paper's table from Python (the same as `bve-mj paper --runs 20`).

python examples/paper_table.py [RUNS]   (default 20 runs per experiment)
"""

from __future__ import annotations

from bve_mj import EXPERIMENTS, Settings, run_table
from bve_mj.cli.script import ScriptParser, guarded, integer
from bve_mj.config.experiments import PAPER_RESULTS
from bve_mj.reporting.tables import format_table


def main(runs: int = 20) -> None:
    summaries = run_table(Settings(), list(EXPERIMENTS.values()), runs=runs, seed=0)
    print("\n".join(format_table(summaries, PAPER_RESULTS)))


if __name__ == "__main__":
    ap = ScriptParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="?", type=integer(1), default=20, help="runs per experiment")
    guarded(lambda: main(ap.parse_args().runs))
