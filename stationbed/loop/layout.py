"""Named layouts of flat vectors (:class:`~stationbed.core.layout.Layout`), re-exported here
where the loop layer declared them first; the class lives in ``core`` so the model and the
formulations (layers below the loop) declare their state and input layouts with it."""

from __future__ import annotations

from ..core.layout import Layout

__all__ = ["Layout"]
