"""Write the goldens of the shipped scenarios (tests/data/golden/README.md says when and how).

    .venv/bin/python tests/data/golden/make_golden.py              # every scenario with a golden
    .venv/bin/python tests/data/golden/make_golden.py iss_lvlh_hold # one, by file stem

Each scene runs as ``stationbed run scenarios/NAME.toml --out DIR`` does (in this process, the
scene's own duration) and its golden, ``tests/data/golden/NAME.json``, is written from the CSV
and ``summary.json`` (tests/golden_helpers.py says what is kept).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # tests/: golden_helpers, scenes

from golden_helpers import golden_path, golden_scenarios, record, run_scene, write_golden  # noqa: E402


def main(argv: list[str]) -> int:
    scenes = golden_scenarios()
    if argv:
        by_stem = {p.stem: p for p in scenes}
        unknown = [a for a in argv if a not in by_stem]
        if unknown:
            print(f"no golden scenario {', '.join(unknown)}; valid: {', '.join(by_stem)}", file=sys.stderr)
            return 2
        scenes = [by_stem[a] for a in argv]
    with tempfile.TemporaryDirectory() as tmp:
        for scene in scenes:
            t0 = time.process_time()
            header, data, summary = run_scene(scene, Path(tmp) / scene.stem)
            write_golden(golden_path(scene), record(header, data, summary), scene)
            print(f"{golden_path(scene)}: {len(data)} rows x {len(header)} columns, "
                  f"{time.process_time() - t0:.2f} s CPU")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
