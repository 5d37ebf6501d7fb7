"""A recording's entity read back from its ``.rrd`` (rerun's chunk reader), for the tests that
check what a person sees in the viewer."""

from __future__ import annotations

import pytest


def entity_rows(path, entity: str) -> tuple[dict | None, list[tuple[float, dict]]]:
    """``(static, rows)`` of ``entity`` in the recording at ``path``: its static components
    ``{component column: value}`` (None: none logged), and each temporal row as ``(t [s],
    {component column: value})`` in the file's order (a later row at the same time after)."""
    rerun_chunk = pytest.importorskip("rerun.chunk")
    static, rows = None, []
    for c in rerun_chunk.RrdReader(path).stream().to_chunks():
        if c.entity_path.lstrip("/") != entity:
            continue
        rb = c.to_record_batch()
        names = [n for n in rb.schema.names if ":" in n]
        if c.is_static:
            static = {n: rb.column(n).to_pylist()[0] for n in names}
            continue
        t = rb.column("sim_time").cast("int64").to_pylist()
        rows += [(t[i] * 1e-9, {n: rb.column(n)[i].as_py() for n in names}) for i in range(rb.num_rows)]
    return static, rows
