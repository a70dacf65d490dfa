"""PNG figures of a tracked run, in the manner of the paper's Fig. 3-5.

matplotlib with the non-interactive Agg backend (no screen needed).
"""

from __future__ import annotations

import numpy as np

from .files import atomic_write

__all__ = ["plot_run", "plot_certificate"]


#: Velocity axis limit, m/s: boxes wider than this (before the first samples
#: contract them) would flatten the plot; the clipping is marked on the figure.
VELOCITY_CLIP = 20.0
#: Displacement axis limit, m.
DISPLACEMENT_CLIP = 1.0


def _clip(lo, hi, limit):
    """Clip a band to ``[-limit, limit]``; also says whether anything was cut."""
    cut = bool(np.any(lo < -limit) or np.any(hi > limit))
    return np.clip(lo, -limit, limit), np.clip(hi, -limit, limit), cut


def _pose_boxes(ax, lo, hi, step, color_of, ls="-"):
    """Outline every ``step``-th box ``[lo_k, hi_k]`` in the (x1, x_n) plane, mm, in colour ``color_of(k)``.

    One polygon collection per run of consecutive boxes of one colour (drawn in the boxes' order): a
    patch per box made the figure's rendering seconds long."""
    from itertools import groupby

    from matplotlib.collections import PolyCollection

    ks = np.arange(0, lo.shape[0], step)
    ends = np.concatenate([lo[ks][:, [0, -1]], hi[ks][:, [0, -1]]], axis=1)
    for color, run in groupby(ks[np.isfinite(ends).all(1)], key=color_of):
        idx = list(run)
        x0, x1 = lo[idx, 0] * 1e3, hi[idx, 0] * 1e3
        y0, y1 = lo[idx, -1] * 1e3, hi[idx, -1] * 1e3
        corners = np.stack([np.stack(c, axis=1) for c in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))], axis=1)
        ax.add_collection(PolyCollection(corners, closed=True, facecolors="none", edgecolors=color, linewidths=0.5,
                                         linestyles=ls))


def _pyplot():
    """matplotlib's pyplot on the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _fit_pose_axes(a, ref):
    """Fit the pose plane's limits (mm, 5 mm margin) to the finite boxes of the bands ``ref``, ``[(lo, hi)]``
    of shape ``(K, n)``, m; left as they are when none is finite."""
    fin = np.concatenate([np.isfinite(lo).all(1) & np.isfinite(hi).all(1) for lo, hi in ref])
    lo_all, hi_all = np.concatenate([lo for lo, _ in ref]), np.concatenate([hi for _, hi in ref])
    if fin.any():
        a.set_xlim(lo_all[fin, 0].min() * 1e3 - 5, hi_all[fin, 0].max() * 1e3 + 5)
        a.set_ylim(lo_all[fin, -1].min() * 1e3 - 5, hi_all[fin, -1].max() * 1e3 + 5)


#: The legend's candidate places in a pose panel, in order of preference, and the part of the axes each
#: legend covers there (fractions of the width and height).
_LEGEND_CORNERS = (("upper right", 1, 1), ("upper left", 0, 1), ("lower left", 0, 0), ("lower right", 1, 0))
_LEGEND_SPAN = (0.4, 0.3)


def _pose_legend(a, bands, points=()):
    """The pose panel's legend in the corner that the fewest boxes of ``bands`` (``[(lo, hi)]``, ``(K, n)``,
    m) and ``points`` (``[(K, n)]``, m) reach, under the axes' limits: matplotlib's ``"best"`` tests every
    box one by one, which took longer than drawing them."""
    (x0, x1), (y0, y1) = a.get_xlim(), a.get_ylim()
    wx, wy = _LEGEND_SPAN[0] * (x1 - x0), _LEGEND_SPAN[1] * (y1 - y0)
    best, fewest = "upper right", None
    for loc, right, top in _LEGEND_CORNERS:
        cx0, cx1 = (x1 - wx, x1) if right else (x0, x0 + wx)
        cy0, cy1 = (y1 - wy, y1) if top else (y0, y0 + wy)
        count = 0
        for lo, hi in bands:
            with np.errstate(invalid="ignore"):
                count += int(np.sum((lo[:, 0] * 1e3 <= cx1) & (hi[:, 0] * 1e3 >= cx0)
                                    & (lo[:, -1] * 1e3 <= cy1) & (hi[:, -1] * 1e3 >= cy0)))
        for p in points:
            count += int(np.sum((p[:, 0] * 1e3 >= cx0) & (p[:, 0] * 1e3 <= cx1)
                                & (p[:, -1] * 1e3 >= cy0) & (p[:, -1] * 1e3 <= cy1)))
        if fewest is None or count < fewest:
            best, fewest = loc, count
    a.legend(loc=best, fontsize=8)


def _save(plt, fig, path, title, bounds):
    """Title the figure (``bounds`` on a second line), write it to ``path`` as a PNG and close it."""
    fig.suptitle(title + (f"\n{bounds}" if bounds else ""))
    fig.tight_layout()
    atomic_write(path, lambda fh: fig.savefig(fh, format="png", dpi=110), binary=True, what="--plot")
    plt.close(fig)


def plot_run(path, t_s, boxes, x_true=None, xd_true=None, k_sing=None, title="", bounds="", truth="true", t=None):
    """Write a 2x2 figure: pose boxes in the plane, velocity enclosure of the last
    coordinate and its integral, the displacement enclosure ``[Δ]`` (Fig. 4),
    and the widths of the pose (mm) and velocity (m/s) boxes (Fig. 5).

    Parameters
    ----------
    path : str or Path
        Output PNG, written by :func:`verifier.files.atomic_write`.
    t_s : float
        Sampling period, s.
    boxes : dict
        ``x_lo, x_hi, xd_lo, xd_hi`` arrays ``(K, n)`` (m, m/s) and ``mode`` ``(K,)``.
    x_true, xd_true : array (K, n), optional
        Ground truth (simulations), drawn on top.
    k_sing : int, optional
        Sample of the singular instant (a labelled vertical line).
    title : str
        Figure title.
    bounds : str
        The bounds the run assumed (eps_q, a_max, t_s...), printed under the title.
    truth : str
        What ``x_true``/``xd_true`` are, for the legend (``"true"``, ``"planned"``).
    t : array (K,), optional
        The samples' times, s from the first (an uneven recording: dropped samples, jittered stamps);
        ``k t_s`` by default.
    """
    plt = _pyplot()
    xl, xh, vl, vh = (np.asarray(boxes[k], dtype=float) for k in ("x_lo", "x_hi", "xd_lo", "xd_hi"))
    K, n = xl.shape
    t = np.arange(K) * t_s if t is None else np.asarray(t, dtype=float) - float(t[0])
    fig, ax = plt.subplots(2, 2, figsize=(11, 8.5))
    _run_pose_panel(ax[0, 0], xl, xh, boxes["mode"], x_true, truth)
    _run_velocity_panel(ax[0, 1], t, vl, vh, xd_true, truth)
    _run_displacement_panel(ax[1, 0], t, vl, vh, x_true, truth)
    _run_width_panel(ax[1, 1], t, xl, xh, vl, vh)
    for a in (ax[0, 1], ax[1, 0], ax[1, 1]):
        if k_sing is not None:
            a.axvline(t[k_sing], color="k", lw=1, ls=":", label="singular instant")
    if k_sing is not None:
        ax[0, 1].legend(loc="best", fontsize=8)
        ax[1, 0].legend(loc="best", fontsize=8)
    _save(plt, fig, path, title, bounds)


def _run_pose_panel(a, xl, xh, mode, x_true, truth):
    """:func:`plot_run`'s pose boxes ``(K, n)``, m, in the plane, coloured by their ``mode`` ``(K,)``."""
    K, n = xl.shape
    step = max(1, K // 400)
    _pose_boxes(a, xl, xh, step, lambda k: {1: "tab:blue", -1: "tab:red"}.get(int(mode[k]), "0.6"))
    for label, color in (("mode +1", "tab:blue"), ("mode -1", "tab:red"), ("undecided", "0.6")):
        a.plot([], [], color=color, lw=1, label=f"pose box, {label}")
    if x_true is not None:
        a.plot(x_true[:, 0] * 1e3, x_true[:, -1] * 1e3, "k-", lw=0.8, label=f"{truth} pose")
    _fit_pose_axes(a, [(xl, xh)])
    _pose_legend(a, [(xl, xh)], [] if x_true is None else [x_true])
    a.set_xlabel("x1 (mm)")
    a.set_ylabel(f"x{n} (mm)")
    a.set_title(f"pose boxes, every {step} sample(s)")


def _run_velocity_panel(a, t, vl, vh, xd_true, truth):
    """:func:`plot_run`'s velocity enclosure (m/s) of the last coordinate over the times ``t``, s."""
    n = vl.shape[1]
    lo, hi, cut = _clip(vl[:, -1], vh[:, -1], VELOCITY_CLIP)
    a.fill_between(t, lo, hi, color="tab:orange", alpha=0.4, label=f"velocity enclosure of x{n}")
    if xd_true is not None:
        a.plot(t, xd_true[:, -1], "k-", lw=0.8, label=f"{truth} velocity")
    a.set_ylabel(f"velocity of x{n} (m/s)")
    a.set_xlabel("t (s)")
    a.set_title(f"velocity (clipped at ±{VELOCITY_CLIP:g} m/s)" if cut else "velocity")
    a.legend(loc="best", fontsize=8)


def _run_displacement_panel(a, t, vl, vh, x_true, truth):
    """:func:`plot_run`'s displacement enclosure ``[Δ]`` (mm) of the last coordinate since the first sample
    (samples at times ``t``, s)."""
    n = vl.shape[1]
    # displacement enclosure: sum of the step times velocity over each step (eq. 8)
    h = np.diff(t)
    dl = np.concatenate([[0.0], np.cumsum(h * vl[1:, -1])])
    dh = np.concatenate([[0.0], np.cumsum(h * vh[1:, -1])])
    lo, hi, cut = _clip(dl, dh, DISPLACEMENT_CLIP)
    a.fill_between(t, lo * 1e3, hi * 1e3, color="tab:green", alpha=0.4, label=r"displacement enclosure $[\Delta]$")
    if x_true is not None:
        a.plot(t, (x_true[:, -1] - x_true[0, -1]) * 1e3, "k-", lw=0.8, label=f"{truth} displacement")
    a.set_ylabel(f"displacement of x{n} since t = 0 (mm)")
    a.set_xlabel("t (s)")
    a.set_title(f"displacement (clipped at ±{DISPLACEMENT_CLIP * 1e3:g} mm)" if cut else "displacement")
    a.legend(loc="best", fontsize=8)


def _run_width_panel(a, t, xl, xh, vl, vh):
    """:func:`plot_run`'s widths of the pose (mm, solid) and velocity (m/s, dashed, right axis) boxes."""
    n = xl.shape[1]
    av = a.twinx()
    for i in range(n):
        a.semilogy(t, np.maximum(xh[:, i] - xl[:, i], 1e-9) * 1e3, label=f"pose x{i + 1}")
        av.semilogy(t, np.maximum(vh[:, i] - vl[:, i], 1e-9), "--", label=f"velocity x{i + 1}")
    a.set_xlabel("t (s)")
    a.set_ylabel("pose box width (mm, solid)")
    av.set_ylabel("velocity box width (m/s, dashed)")
    a.set_title("box widths")
    handles = a.get_legend_handles_labels()
    more = av.get_legend_handles_labels()
    a.legend(handles[0] + more[0], handles[1] + more[1], loc="best", fontsize=8)


#: Colours of the final-mode hypotheses of window reasoning.
_HYPOTHESIS_COLOR = {1: "tab:blue", -1: "tab:red"}


def plot_certificate(path, t_s, forward, window, x_plan=None, xd_plan=None, k_sing=None, title="", bounds="",
                     forward_label="forward pass"):
    """Write the figure of a certified run: what certified it, drawn as such.

    The window passes' tubes of each final-mode hypothesis that survived
    (hull over its surviving geometry sub-boxes), the refuted hypothesis
    named with its reason, and the forward pass drawn beside them only as
    "forward pass" (its boxes are not what certified the run).

    Parameters
    ----------
    path : str or Path
        Output PNG, written by :func:`verifier.files.atomic_write`.
    t_s : float
        Sampling period, s.
    forward : dict
        The forward pass: ``x_lo, x_hi, xd_lo, xd_hi`` ``(K, n)`` (m, m/s) and ``mode`` ``(K,)``.
    window : verifier.window.WindowResult
        The window passes on the same readings.
    x_plan, xd_plan : array (K, n), optional
        Planned pose (m) and velocity (m/s), drawn on top.
    k_sing : int, optional
        Sample of the singular instant.
    title, bounds : str
        Figure title and the bounds the run assumed (printed under it).
    forward_label : str
        What ``forward`` is (e.g. the online monitor's boxes: the tracker, re-seeded in the decided mode).
    """
    plt = _pyplot()
    fl, fh, fvl, fvh = (np.asarray(forward[k], dtype=float) for k in ("x_lo", "x_hi", "xd_lo", "xd_hi"))
    K, n = fl.shape
    t = np.arange(K) * t_s
    # a surviving hypothesis that ran no pass has the forward pass's tubes (both modes after the locus): it is
    # not drawn as a window tube; ``forward`` shows the run (e.g. the decided mode's boxes after a decision)
    alive = [h for h in window.hypotheses if h.x_lo is not None and h.passes > 0]
    fig, ax = plt.subplots(2, 2, figsize=(11, 8.5))
    _certificate_pose_panel(ax[0, 0], fl, fh, alive, x_plan, forward_label)
    _certificate_velocity_panel(ax[0, 1], t, fvl, fvh, alive, xd_plan, forward_label)
    _certificate_width_panel(ax[1, 0], t, fl, fh, fvl, fvh, alive, forward_label)
    for a in (ax[0, 1], ax[1, 0]):
        if k_sing is not None:
            a.axvline(t[k_sing], color="k", lw=1, ls=":", label="singular instant")
        a.legend(loc="best", fontsize=8)
    _reasoning_panel(ax[1, 1], window)
    _save(plt, fig, path, title, bounds)


def _certificate_pose_panel(a, fl, fh, alive, x_plan, forward_label):
    """:func:`plot_certificate`'s pose boxes in the plane: the tubes of the hypotheses ``alive``, each in its
    colour, and the forward pass's boxes ``(K, n)``, m, in grey."""
    K, n = fl.shape
    step = max(1, K // 300)
    # the forward pass last, dotted, so that it shows where a tube coincides with it
    layers = [(f"window tube, final mode {h.final_mode:+d}", _HYPOTHESIS_COLOR.get(h.final_mode, "k"), "-", h.x_lo, h.x_hi)
              for h in alive] + [(forward_label, "0.35", ":" if alive else "-", fl, fh)]
    for label, color, ls, lo, hi in layers:
        _pose_boxes(a, lo, hi, step, lambda k, c=color: c, ls)
        a.plot([], [], color=color, lw=1, ls=ls, label=label)
    if x_plan is not None:
        a.plot(x_plan[:, 0] * 1e3, x_plan[:, -1] * 1e3, "k-", lw=0.8, label="planned pose")
    _fit_pose_axes(a, [(h.x_lo, h.x_hi) for h in alive] or [(fl, fh)])
    a.set_xlabel("x1 (mm)")
    a.set_ylabel(f"x{n} (mm)")
    a.set_title(f"pose boxes, every {step} sample(s)")
    _pose_legend(a, [(lo, hi) for _, _, _, lo, hi in layers], [] if x_plan is None else [x_plan])


def _certificate_velocity_panel(a, t, fvl, fvh, alive, xd_plan, forward_label):
    """:func:`plot_certificate`'s velocity (m/s) of the last coordinate: the hypotheses' tubes and the forward
    pass's bounds over the times ``t``, s."""
    n = fvl.shape[1]
    cut = False
    for h in alive:
        lo, hi, c = _clip(h.xd_lo[:, -1], h.xd_hi[:, -1], VELOCITY_CLIP)
        cut |= c
        a.fill_between(t, lo, hi, color=_HYPOTHESIS_COLOR.get(h.final_mode, "k"), alpha=0.45,
                       label=f"window tube, final mode {h.final_mode:+d}")
    lo, hi, c = _clip(fvl[:, -1], fvh[:, -1], VELOCITY_CLIP)
    cut |= c
    a.plot(t, lo, color="0.35", ls=":", lw=1, label=forward_label)
    a.plot(t, hi, color="0.35", ls=":", lw=1)
    if xd_plan is not None:
        a.plot(t, xd_plan[:, -1], "k-", lw=0.8, label="planned velocity")
    a.set_ylabel(f"velocity of x{n} (m/s)")
    a.set_xlabel("t (s)")
    a.set_title(f"velocity (clipped at ±{VELOCITY_CLIP:g} m/s)" if cut else "velocity")


def _certificate_width_panel(a, t, fl, fh, fvl, fvh, alive, forward_label):
    """:func:`plot_certificate`'s largest box sides, pose (mm, solid) and velocity (m/s, dashed): what each
    reasoning leaves."""
    a.semilogy(t, np.maximum((fh - fl).max(axis=1), 1e-9) * 1e3, color="0.6", label=f"pose, {forward_label}")
    a.semilogy(t, np.maximum((fvh - fvl).max(axis=1), 1e-9), color="0.6", ls="--",
               label=f"velocity, {forward_label}")
    for h in alive:
        color = _HYPOTHESIS_COLOR.get(h.final_mode, "k")
        a.semilogy(t, np.maximum((h.x_hi - h.x_lo).max(axis=1), 1e-9) * 1e3, color=color,
                   label=f"pose, final mode {h.final_mode:+d}")
        a.semilogy(t, np.maximum((h.xd_hi - h.xd_lo).max(axis=1), 1e-9), color=color, ls="--",
                   label=f"velocity, final mode {h.final_mode:+d}")
    a.set_xlabel("t (s)")
    a.set_ylabel("largest box side (mm solid, m/s dashed)")
    a.set_title("box widths")


def _reasoning_panel(a, window):
    """:func:`plot_certificate`'s text panel: the window's verdict and the reasoning, hypothesis by hypothesis."""
    a.axis("off")
    lines = [f"verdict: {window.verdict.value} (forward pass alone: {window.forward_verdict.value})", ""]
    for h in window.hypotheses:
        if h.status.value == "refuted":
            lines.append(f"final mode {h.final_mode:+d}: REFUTED ({h.refutation.value}) after {h.passes} pass(es)")
        else:
            lines.append(f"final mode {h.final_mode:+d}: consistent, {h.geometries_alive} geometry sub-box(es) "
                         f"alive after {h.passes} pass(es)")
    lines += ["", "A hypothesis is refuted when no admissible motion ends in", "its final mode: the run's mode is the other one."]
    a.text(0.0, 1.0, "\n".join(lines), va="top", ha="left", fontsize=9, family="monospace", transform=a.transAxes)
    a.set_title("window reasoning")
