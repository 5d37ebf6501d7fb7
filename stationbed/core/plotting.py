"""matplotlib (extra ``plot``) on the headless Agg backend, imported only when a chart is drawn."""

from __future__ import annotations

__all__ = ["pyplot", "save_png", "fit_legends", "legend_inside"]

#: the smallest font a legend is shrunk to [pt] before it is left as it is
LEGEND_MIN_FONT_PT = 5.0
#: a legend may touch its axes' frame by this much [pixel] (anti-aliasing of the two boxes)
LEGEND_SLACK_PX = 1.0


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
    """Lay ``fig`` out, keep its legends inside their axes (:func:`fit_legends`), write it as a
    PNG at ``path`` and free it; ``title_in`` [inch] is kept free above the panels for a suptitle
    (tight_layout leaves none)."""
    fig.set_dpi(dpi)  # the layout and the legends' sizes in the pixels of the file
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 1.0 - title_in / fig.get_figheight()))
    fit_legends(fig)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


def legend_inside(ax, renderer=None) -> bool:
    """Whether the legend of ``ax`` (if any) lies inside the axes' box (a twin's box is its host's)."""
    leg = ax.get_legend()
    if leg is None:
        return True
    renderer = renderer or ax.figure.canvas.get_renderer()
    a, b = ax.get_window_extent(renderer), leg.get_window_extent(renderer)
    s = LEGEND_SLACK_PX
    return b.x0 >= a.x0 - s and b.x1 <= a.x1 + s and b.y0 >= a.y0 - s and b.y1 <= a.y1 + s


def fit_legends(fig) -> None:
    """Keep every legend of ``fig`` inside its axes: fewer columns, then a smaller font (down to
    :data:`LEGEND_MIN_FONT_PT`), until it fits; a legend that fits is left as drawn."""
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:
        leg = ax.get_legend()
        if leg is None or not ax.get_visible() or legend_inside(ax, renderer):
            continue
        handles, labels = leg.legend_handles, [t.get_text() for t in leg.get_texts()]
        ncol, size, loc = leg._ncols, leg.get_texts()[0].get_fontsize() if labels else 7.0, leg._loc
        while not legend_inside(ax, renderer):
            if ncol > 1:
                ncol -= 1
            elif size > LEGEND_MIN_FONT_PT:
                size -= 1.0
            else:
                break
            leg.remove()
            leg = ax.legend(handles, labels, ncol=ncol, fontsize=size, loc=loc)
