"""matplotlib (extra ``plot``) on the headless Agg backend, imported only when a chart is drawn."""

from __future__ import annotations

__all__ = ["pyplot", "save_png"]


def pyplot(missing: type[Exception] = ValueError):
    """matplotlib's pyplot on the Agg backend (files only).

    Parameters
    ----------
    missing : exception class  Raised, with a one-line message saying how to install it, when
        matplotlib is not installed (each caller's own error type, so its command reports it).

    Returns
    -------
    module
        ``matplotlib.pyplot``.
    """
    try:
        import matplotlib
    except ImportError:
        raise missing("charts are drawn with matplotlib, which is not installed: "
                      "pip install 'stationbed[plot]' (or pip install matplotlib)") from None
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def save_png(plt, fig, path, dpi: int = 110, title_in: float = 0.0) -> None:
    """Lay ``fig`` out, write it as a PNG at ``path`` and free it; ``title_in`` [inch] is kept
    free above the panels for a suptitle (tight_layout leaves none)."""
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 1.0 - title_in / fig.get_figheight()))
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
