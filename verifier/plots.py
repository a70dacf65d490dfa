"""PNG figures of a tracked run, in the manner of the paper's Fig. 3-5.

matplotlib with the non-interactive Agg backend (no screen needed).
"""

from __future__ import annotations

import numpy as np

from .files import atomic_write

__all__ = ["plot_run"]


def plot_run(path, t_s, boxes, x_true=None, xd_true=None, k_sing=None, title=""):
    """Write a 2x2 figure: pose boxes in the plane, velocity enclosure of the
    last coordinate with its integral ``[Delta]`` (Fig. 4), and box widths (Fig. 5).

    Parameters
    ----------
    path : str or Path
        Output PNG.
    t_s : float
        Sampling period, s.
    boxes : dict
        ``x_lo, x_hi, xd_lo, xd_hi`` arrays ``(K, n)`` and ``mode`` ``(K,)``.
    x_true, xd_true : array (K, n), optional
        Ground truth (simulations), drawn on top.
    k_sing : int, optional
        Sample of the singular instant (a vertical line).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    xl, xh, vl, vh = (np.asarray(boxes[k]) for k in ("x_lo", "x_hi", "xd_lo", "xd_hi"))
    K, n = xl.shape
    t = np.arange(K) * t_s
    fig, ax = plt.subplots(2, 2, figsize=(11, 8))
    a = ax[0, 0]
    step = max(1, K // 400)
    for k in range(0, K, step):
        if np.all(np.isfinite([xl[k, 0], xh[k, 0], xl[k, -1], xh[k, -1]])):
            color = {1: "tab:blue", -1: "tab:red"}.get(int(boxes["mode"][k]), "0.6")
            a.add_patch(Rectangle((xl[k, 0] * 1e3, xl[k, -1] * 1e3), (xh[k, 0] - xl[k, 0]) * 1e3,
                                  (xh[k, -1] - xl[k, -1]) * 1e3, fill=False, lw=0.5, ec=color))
    if x_true is not None:
        a.plot(x_true[:, 0] * 1e3, x_true[:, -1] * 1e3, "k-", lw=0.8, label="true pose")
        a.legend(loc="best")
    fin = np.isfinite(xl).all(1) & np.isfinite(xh).all(1)
    if fin.any():
        a.set_xlim(xl[fin, 0].min() * 1e3 - 5, xh[fin, 0].max() * 1e3 + 5)
        a.set_ylim(xl[fin, -1].min() * 1e3 - 5, xh[fin, -1].max() * 1e3 + 5)
    a.set_xlabel("x1 (mm)")
    a.set_ylabel(f"x{n} (mm)")
    a.set_title("pose boxes (blue +1, red -1, grey undecided)")
    a = ax[0, 1]
    a.fill_between(t, np.clip(vl[:, -1], -20, 20), np.clip(vh[:, -1], -20, 20), color="tab:orange", alpha=0.4, label="enclosure")
    if xd_true is not None:
        a.plot(t, xd_true[:, -1], "k-", lw=0.8, label="true")
    a.set_ylabel(f"velocity x{n} (m/s)")
    a.set_xlabel("t (s)")
    a.legend(loc="best")
    a = ax[1, 0]
    # displacement enclosure: sum of t_s * velocity over each step (eq. 8)
    dl = np.concatenate([[0.0], np.cumsum(t_s * vl[1:, -1])])
    dh = np.concatenate([[0.0], np.cumsum(t_s * vh[1:, -1])])
    a.fill_between(t, np.clip(dl, -1, 1) * 1e3, np.clip(dh, -1, 1) * 1e3, color="tab:green", alpha=0.4, label="[Delta]")
    if x_true is not None:
        a.plot(t, (x_true[:, -1] - x_true[0, -1]) * 1e3, "k-", lw=0.8, label="true")
    a.set_ylabel(f"displacement x{n} (mm)")
    a.set_xlabel("t (s)")
    a.legend(loc="best")
    a = ax[1, 1]
    for i in range(n):
        a.semilogy(t, np.maximum(xh[:, i] - xl[:, i], 1e-9) * 1e3, label=f"width x{i + 1} (mm)")
        a.semilogy(t, np.maximum(vh[:, i] - vl[:, i], 1e-9), "--", label=f"width xd{i + 1} (m/s)")
    a.set_xlabel("t (s)")
    a.legend(loc="best", fontsize=8)
    for a in (ax[0, 1], ax[1, 0], ax[1, 1]):
        if k_sing is not None:
            a.axvline(k_sing * t_s, color="k", lw=1)
    fig.suptitle(title)
    fig.tight_layout()
    atomic_write(path, lambda fh: fig.savefig(fh, format="png", dpi=110), binary=True, what="--plot")
    plt.close(fig)
