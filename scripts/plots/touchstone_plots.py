#!/usr/bin/python3
"""Figures of a Touchstone experiment report (the JSON of `touchstone report --json`).

    /usr/bin/python3 scripts/plots/touchstone_plots.py REPORT.json --out DIR

Writes into DIR:
  recognition_rate.png        recognition rate against step, Wilson 95 % band (per variant)
  pose_errors.png             position and orientation error against step: mean bounded by the
                              paper's 4 cm / 1 rad with Student-t 95 % band, and the median
  time_per_step.png           time per step (median, 95th percentile) and per-stage medians
  error_vs_time.png           error against time per step: per step, or the Pareto front of a sweep
  recognition_per_object.png  recognition rate per object and step (several objects only)

Given the scenes of `touchstone recognize --scene DIR` (DIR/scenes.json, {"scenes": [...]})
instead, writes for each scene:
  scene_<input>_step<k>.png   contacts, free space, the leading hypotheses' objects at their poses
                              and the true object, seen from two sides
  scene_<input>_step<k>.html  the same as an interactive page (drag to turn, wheel to zoom); the
                              data and the viewer are inside the file, nothing is fetched

Uses only matplotlib and numpy (Debian's python3-matplotlib for /usr/bin/python3).
"""
import argparse
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

plt.rcParams.update({
    "font.size": 9,
    "axes.titlesize": 9,
    "axes.labelsize": 9,
    "legend.fontsize": 7.5,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "grid.linewidth": 0.5,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "savefig.dpi": 200,
    "savefig.bbox": "tight",
    "lines.linewidth": 1.4,
})
COLORS = plt.rcParams["axes.prop_cycle"].by_key()["color"]
WIDTH = 6.8  # inches: a two-column paper's full width


def column(rows, key, scale=1.0):
    """Values of `key` in per-step rows as floats (nan where null)."""
    out = []
    for r in rows:
        v = r.get(key)
        out.append(np.nan if v is None else float(v) * scale)
    return np.array(out, dtype=float)


def band(rows, key, scale=1.0):
    lo, hi = [], []
    for r in rows:
        v = r.get(key)
        if v is None:
            lo.append(np.nan)
            hi.append(np.nan)
        else:
            lo.append(float(v[0]) * scale)
            hi.append(float(v[1]) * scale)
    return np.array(lo), np.array(hi)


def series(report):
    """(label, per_step rows) for each variant, or the single experiment."""
    if "variants" in report:
        return [(v["label"], v["per_step"]) for v in report["variants"] if v["per_step"]]
    return [(report["config"].get("name", "experiment"), report["per_step"])]


def subtitle(report):
    c = report["config"]
    st = report["store"]
    objects = len(st.get("objects", []))
    # A key the sweep varies is named by the variants' labels, not the configuration's base value.
    swept = c.get("sweep") or {}
    noise = c.get("noise", "?") if len(swept.get("noise", [])) <= 1 else "swept"
    if len(swept.get("noise", [])) == 1:
        noise = swept["noise"][0]
    method = c.get("method", "?") if "method" not in swept else "swept"
    sensors = c.get("sensors", "?") if "sensors" not in swept else "swept"
    text = (f"{method}, {noise} noise, {sensors} pad(s), "
            f"{objects} object{'s' if objects != 1 else ''}, {st.get('runs_done', 0)} runs")
    if not st.get("complete", True):
        text += f" (of {st.get('runs_planned', '?')})"
    return text


def steps_of(rows):
    return np.array([r["step"] for r in rows], dtype=float)


def finish(fig, path, written):
    fig.savefig(path)
    plt.close(fig)
    written.append(path)


def plot_recognition(report, out, written):
    fig, ax = plt.subplots(figsize=(WIDTH / 2, 2.6))
    for i, (label, rows) in enumerate(series(report)):
        x = steps_of(rows)
        y = column(rows, "recognition_rate", 100)
        lo, hi = band(rows, "recognition_rate_ci95", 100)
        c = COLORS[i % len(COLORS)]
        ax.fill_between(x, lo, hi, color=c, alpha=0.18, linewidth=0)
        # The cluster bootstrap over objects (absent in old reports, null for one object).
        blo, bhi = band(rows, "recognition_rate_cluster_ci95", 100)
        if np.isfinite(blo).any():
            ax.plot(x, blo, color=c, linestyle=":", linewidth=0.9)
            ax.plot(x, bhi, color=c, linestyle=":", linewidth=0.9)
        ax.plot(x, y, color=c, marker="o", markersize=2.5, label=label)
    ax.set_xlabel("exploration step (grasps)")
    ax.set_ylabel("recognition rate (%)")
    ax.set_ylim(-2, 102)
    ax.set_xlim(left=0.5)
    ax.set_title(subtitle(report))
    protocol = report.get("intervals", {}).get("protocol", "shared_pool")
    ax.legend(loc="lower right", frameon=False, title_fontsize=7,
              title=f"protocol {protocol}\nshaded: Wilson 95 % (runs independent)\n"
                    "dotted: bootstrap over objects 95 %")
    finish(fig, os.path.join(out, "recognition_rate.png"), written)


def plot_errors(report, out, written):
    fig, axes = plt.subplots(1, 2, figsize=(WIDTH, 2.6))
    specs = [
        (axes[0], "position_error_m", 1000, "position error (mm)", 40),
        (axes[1], "symmetric_orientation_error_deg", 1, "orientation error (deg)", 57.3),
    ]
    many = len(series(report)) > 1
    for ax, key, scale, ylabel, bound in specs:
        peak = 0.0  # of the lines (not the bands, which are wide for few runs)
        for i, (label, rows) in enumerate(series(report)):
            x = steps_of(rows)
            c = COLORS[i % len(COLORS)]
            mean = column(rows, key + "_mean_bounded", scale)
            lo, hi = band(rows, key + "_mean_bounded_ci95", scale)
            med = column(rows, key + "_median", scale)
            ax.fill_between(x, lo, hi, color=c, alpha=0.18, linewidth=0)
            peak = np.nanmax([peak, np.nanmax(mean, initial=0.0), np.nanmax(med, initial=0.0)])
            ax.plot(x, mean, color=c, label=(label if many else "bounded mean, 95 % CI"))
            ax.plot(x, med, color=c, linestyle="--", linewidth=1.0,
                    label=(None if many else "median"))
            if key == "symmetric_orientation_error_deg" and not many:
                raw = column(rows, "orientation_error_deg_median", scale)
                ax.plot(x, raw, color="0.5", linestyle=":", linewidth=1.0,
                        label="median, ignoring symmetry")
        ax.axhline(bound, color="0.4", linewidth=0.6, linestyle="-.")
        ax.text(0.01, bound, " bound used for averaging (paper)", transform=ax.get_yaxis_transform(),
                ha="left", va="bottom", fontsize=6.5, color="0.4")
        ax.set_xlabel("exploration step (grasps)")
        ax.set_ylabel(ylabel)
        ax.set_ylim(0, max(bound * 1.45, peak * 1.1))
        ax.set_xlim(left=0.5)
    axes[0].set_title("position (runs with the right object)")
    axes[1].set_title("orientation, symmetry-aware")
    axes[0].legend(frameon=False, loc="upper right", fontsize=6.5)
    if not many:
        axes[1].legend(frameon=False, loc="upper right", fontsize=6.5)
    fig.tight_layout()
    fig.suptitle(subtitle(report), fontsize=8, y=1.04)
    finish(fig, os.path.join(out, "pose_errors.png"), written)


def plot_time(report, out, written):
    fig, axes = plt.subplots(1, 2, figsize=(WIDTH, 2.6))
    ax = axes[0]
    for i, (label, rows) in enumerate(series(report)):
        x = steps_of(rows)
        c = COLORS[i % len(COLORS)]
        ax.plot(x, column(rows, "time_s_median"), color=c, label=label)
        ax.plot(x, column(rows, "time_s_p95"), color=c, linestyle="--", linewidth=1.0)
    ax.set_xlabel("exploration step (grasps)")
    ax.set_ylabel("time per step (s)")
    ax.set_ylim(bottom=0)
    ax.set_title("median (solid), 95th percentile (dashed)")
    if len(series(report)) > 1:
        ax.legend(frameon=False, fontsize=6.5)
    # Per-stage medians of the first series, stacked.
    ax = axes[1]
    rows = series(report)[0][1]
    stages = list(rows[0].get("stage_times_s_median", {}).keys()) if rows else []
    if stages:
        x = steps_of(rows)
        ys = [np.nan_to_num(np.array([np.nan if r["stage_times_s_median"].get(s) is None
                                      else r["stage_times_s_median"][s] for r in rows], dtype=float))
              for s in stages]
        ax.stackplot(x, ys, labels=stages, colors=COLORS[:len(stages)], alpha=0.85)
        ax.legend(frameon=False, loc="upper left", fontsize=6.5)
        ax.set_title("per-stage medians" + (f" ({series(report)[0][0]})" if len(series(report)) > 1 else ""))
    else:
        ax.text(0.5, 0.5, "no per-stage timings", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("exploration step (grasps)")
    ax.set_ylabel("time (s)")
    ax.set_ylim(bottom=0)
    fig.tight_layout()
    fig.suptitle(subtitle(report) + f"; {report.get('threads')} threads, {report.get('machine')}",
                 fontsize=7.5, y=1.04)
    finish(fig, os.path.join(out, "time_per_step.png"), written)


def short_labels(labels):
    """("key1, key2", ["v1, v2", ...]) when every label sets the same keys; else the labels."""
    parsed = [[part.split("=", 1) for part in label.split(", ")] if label else [] for label in labels]
    keys = [tuple(kv[0] for kv in p) for p in parsed]
    if labels and all(len(kv) == 2 for p in parsed for kv in p) and len(set(keys)) == 1 and keys[0]:
        return ", ".join(keys[0]), [", ".join(kv[1] for kv in p) for p in parsed]
    return "", list(labels)


def plot_error_vs_time(report, out, written):
    fig, axes = plt.subplots(1, 2, figsize=(WIDTH, 2.9))
    if "variants" in report:
        variants = [v for v in report["variants"] if v.get("summary")]
        title, names = short_labels([v["label"] for v in variants])
        pareto = report.get("pareto", {})
        specs = [
            (axes[0], "recognition_rate_final", 100, "recognition rate at the last step (%)",
             pareto.get("recognition_rate_final", [])),
            (axes[1], "position_error_m_median_final", 1000, "median position error, last step (mm)",
             pareto.get("position_error_m_median_final", [])),
        ]
        for ax, key, scale, ylabel, front in specs:
            xs = np.array([v["summary"]["time_s_per_step_mean"] for v in variants], dtype=float)
            ys = np.array([np.nan if v["summary"][key] is None else v["summary"][key] * scale
                           for v in variants], dtype=float)
            on = np.array([v["label"] in front for v in variants])
            ax.scatter(xs[~on], ys[~on], s=14, color="0.6", label="dominated", zorder=2)
            ax.scatter(xs[on], ys[on], s=20, color=COLORS[3], label="Pareto front", zorder=3)
            if on.any():
                order = np.argsort(xs[on])
                ax.step(xs[on][order], ys[on][order], where="post", color=COLORS[3], linewidth=1.0)
            for i, (name, x, y) in enumerate(zip(names, xs, ys)):
                if np.isfinite(y):
                    ax.annotate(name.replace(", ", "\n"), (x, y), fontsize=6,
                                xytext=(4, 4 if i % 2 == 0 else -9), textcoords="offset points")
            ax.set_xscale("log")
            ax.margins(x=0.25, y=0.15)
            ax.set_xlabel("mean time per step (s, log scale)")
            ax.set_ylabel(ylabel)
        axes[0].set_ylim(top=min(105, axes[0].get_ylim()[1]))
        axes[1].set_ylim(bottom=0)
        axes[0].legend(frameon=False, loc="best", title=title or None, title_fontsize=6.5)
        fig.tight_layout(w_pad=2.0)
        fig.suptitle("error against run time: " + subtitle(report), fontsize=8, y=1.04)
    else:
        rows = report["per_step"]
        t = column(rows, "time_s_median")
        steps = steps_of(rows)
        for ax, key, scale, ylabel in [
            (axes[0], "position_error_m_median", 1000, "median position error (mm)"),
            (axes[1], "symmetric_orientation_error_deg_median", 1, "median orientation error (deg)"),
        ]:
            y = column(rows, key, scale)
            sc = ax.scatter(t, y, c=steps, cmap="viridis", s=16, zorder=3)
            ax.plot(t, y, color="0.7", linewidth=0.8, zorder=2)
            ax.set_xlabel("median time of the step (s)")
            ax.set_ylabel(ylabel)
            ax.set_ylim(bottom=0)
        cb = fig.colorbar(sc, ax=axes, fraction=0.03, pad=0.02)
        cb.set_label("step")
        fig.suptitle("error against time per step: " + subtitle(report), fontsize=8, y=1.02)
    finish(fig, os.path.join(out, "error_vs_time.png"), written)


def plot_per_object(report, out, written):
    objs = report.get("per_object", [])
    if len(objs) < 2:
        return
    names = [o["object"] for o in objs]
    grid = np.array([column(o["per_step"], "recognition_rate", 100) for o in objs])
    steps = grid.shape[1]
    fig, ax = plt.subplots(figsize=(WIDTH, 0.6 + 0.16 * len(names)))
    im = ax.imshow(grid, aspect="auto", cmap="viridis", vmin=0, vmax=100, interpolation="nearest",
                   extent=(0.5, steps + 0.5, len(names) - 0.5, -0.5))
    ax.set_yticks(range(len(names)))
    ax.set_yticklabels(names, fontsize=6.5)
    ax.set_xlabel("exploration step (grasps)")
    ax.grid(False)
    cb = fig.colorbar(im, ax=ax, fraction=0.025, pad=0.01)
    cb.set_label("recognition rate (%)")
    ax.set_title("per object: " + subtitle(report))
    finish(fig, os.path.join(out, "recognition_per_object.png"), written)


def plot_reliability(report, out, written):
    """Reliability diagrams of the step confidences (object right; pose within 1 cm)."""
    conf = report.get("confidence")
    if not conf:
        return
    fig, axes = plt.subplots(1, 2, figsize=(WIDTH, 2.9))
    panels = [("object", "object right"), ("pose", "right object, position < 1 cm")]
    for ax, (key, title) in zip(axes, panels):
        ax.plot([0, 1], [0, 1], color="0.6", linestyle="--", linewidth=0.9)
        sets = [("all steps", conf["all_steps"][key + "_reliability"], COLORS[0])]
        if conf.get("step20_reliability"):
            step = min(20, len(conf["per_step"]))
            sets.append((f"step {step}", conf["step20_reliability"][key], COLORS[1]))
        for label, bins, c in sets:
            x = [b["mean_confidence"] for b in bins if b["n"] > 0]
            y = [b["accuracy"] for b in bins if b["n"] > 0]
            n = [b["n"] for b in bins if b["n"] > 0]
            total = max(1, sum(n))
            ax.plot(x, y, color=c, marker="o", markersize=3, label=label)
            for xi, yi, ni in zip(x, y, n):
                ax.scatter([xi], [yi], s=8 + 200 * ni / total, color=c, alpha=0.25, linewidths=0)
        a = conf["all_steps"]
        ax.set_title(f"{title}\nall steps: ECE {a[key + '_ece']:.3f}, Brier {a[key + '_brier']:.3f}",
                     fontsize=7.5)
        ax.set_xlabel("confidence")
        ax.set_ylabel("share right")
        ax.set_xlim(-0.02, 1.02)
        ax.set_ylim(-0.02, 1.02)
        ax.legend(loc="upper left", frameon=False, fontsize=7)
    source = os.path.basename(conf.get("source", "").split(" with ")[-1])
    fig.suptitle(f"reliability: {subtitle(report)} (confidence: {source})", fontsize=7.5, y=1.04)
    finish(fig, os.path.join(out, "reliability.png"), written)


SCENE_COLOURS = {"contacts": "#d62728", "free": "#9ecae1", "truth": "#7f7f7f",
                 "hypotheses": ["#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2"]}


def is_answer(scene, h):
    """Whether a drawn hypothesis is the step's answer (scenes before "answer" was written: the first)."""
    if "answer" in h:
        return bool(h["answer"])
    return h is scene.get("hypotheses", [None])[0]


def hypothesis_label(h, answer):
    """'#2 hand: posterior 0.110' (the share of the state's weight, which ranks them); the answer
    adds its calibrated confidence, or says that the posterior is not one."""
    text = "#%d %s: posterior %.3f" % (h["rank"], h["object"], h["posterior"])
    if not answer:
        return text
    if h.get("confidence") is not None:
        return text + " (the answer; calibrated confidence %.2f)" % h["confidence"]
    return text + " (the answer; a share of the weight, not a calibrated probability)"


def answer_name(scene):
    """The object the step named (older scenes: the first drawn), or 'nothing'."""
    if "answer" in scene:
        return scene["answer"] if scene["answer"] is not None else "nothing"
    return scene["hypotheses"][0]["object"] if scene.get("hypotheses") else "nothing"


def scene_layers(scene):
    """The drawn layers, back to front: (label, points N x 3, colour, size, opacity). The leading
    hypothesis is drawn solid, its rivals faint, the truth as a larger grey shell behind them."""
    layers = []
    if scene.get("free"):
        layers.append(("free space (%d of %d points)" % (len(scene["free"]), scene.get("free_total", 0)),
                       np.asarray(scene["free"], float), SCENE_COLOURS["free"], 1.5, 0.6))
    truth = scene.get("truth")
    if truth:
        layers.append(("truth: %s" % truth["object"], np.asarray(truth["points"], float),
                       SCENE_COLOURS["truth"], 3.0, 0.25))
    hypotheses = scene.get("hypotheses", [])
    # Ranked by the object's posterior, the number each label shows; the answer drawn solid, on top.
    # Drawn rivals from the last rank up, then the answer; the legend reverses the drawing order.
    order = [i for i in reversed(range(len(hypotheses))) if not is_answer(scene, hypotheses[i])] + \
            [i for i in range(len(hypotheses)) if is_answer(scene, hypotheses[i])]
    for i in order:
        h = hypotheses[i]
        colour = SCENE_COLOURS["hypotheses"][i % len(SCENE_COLOURS["hypotheses"])]
        answer = is_answer(scene, h)
        layers.append((hypothesis_label(h, answer), np.asarray(h["points"], float), colour,
                       1.6 if answer else 1.0, 0.9 if answer else 0.25))
    if scene.get("contacts"):
        layers.append(("contacts (%d)" % len(scene["contacts"]), np.asarray(scene["contacts"], float),
                       SCENE_COLOURS["contacts"], 5.0, 1.0))
    return [layer for layer in layers if layer[1].size]


def plot_scene(scene, out, written):
    layers = scene_layers(scene)
    stem = os.path.join(out, "scene_%s_step%d" % (scene["name"], scene["step"]))
    fig = plt.figure(figsize=(10, 5))
    everything = np.vstack([layer[1] for layer in layers]) if layers else np.zeros((1, 3))
    centre = 0.5 * (everything.min(0) + everything.max(0))
    half = 0.5 * max(float((everything.max(0) - everything.min(0)).max()), 1e-3)
    for k, (elev, azim) in enumerate([(25, -60), (25, 30)]):
        ax = fig.add_subplot(1, 2, k + 1, projection="3d")
        for label, pts, colour, size, alpha in layers:
            ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], s=size, c=colour, alpha=alpha, label=label,
                       depthshade=False, linewidths=0)
        for axis, c in zip("xyz", centre):
            getattr(ax, "set_%slim" % axis)(c - half, c + half)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=elev, azim=azim)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_zlabel("z (m)")
        ax.set_title("azimuth %d°" % azim)
    handles, labels = fig.axes[0].get_legend_handles_labels()
    # The legend reads contacts, the answer, its rivals by rank, truth, free space (the drawing order
    # reversed).
    handles, labels = handles[::-1], labels[::-1]
    legend = fig.legend(handles, labels, loc="lower center", ncol=3, markerscale=4, frameon=False)
    for handle in legend.legend_handles if hasattr(legend, "legend_handles") else legend.legendHandles:
        handle.set_alpha(1.0)
    best = answer_name(scene)
    fig.suptitle("%s: named %s%s" % (scene["label"], best,
                                     ", truth %s" % scene["truth"]["object"] if scene.get("truth") else ""))
    fig.subplots_adjust(bottom=0.16)
    fig.savefig(stem + ".png")
    plt.close(fig)
    written.append(stem + ".png")
    with open(stem + ".html", "w") as f:
        f.write(scene_html(scene, layers))
    written.append(stem + ".html")


SCENE_VIEWER = """<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>%(title)s</title>
<style>body{font:13px sans-serif;margin:8px}canvas{border:1px solid #ccc;cursor:grab}
.key span{display:inline-block;width:10px;height:10px;margin:0 4px 0 12px}</style></head>
<body><div><b>%(title)s</b> &mdash; drag to turn, wheel to zoom</div>
<canvas id="c" width="900" height="650"></canvas><div class="key" id="key"></div>
<script>
const layers = %(layers)s;
const cv = document.getElementById("c"), g = cv.getContext("2d");
let yaw = -0.9, pitch = 0.45, zoom = 1.0, drag = null;
let lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
for (const L of layers) for (const p of L.points) for (let i = 0; i < 3; i++) {
  lo[i] = Math.min(lo[i], p[i]); hi[i] = Math.max(hi[i], p[i]); }
const mid = lo.map((v, i) => (v + hi[i]) / 2);
const span = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 1e-3);
function draw() {
  g.fillStyle = "#fff"; g.fillRect(0, 0, cv.width, cv.height);
  const cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
  const s = zoom * 0.8 * Math.min(cv.width, cv.height) / span, pts = [];
  for (const L of layers) for (const p of L.points) {
    const x = p[0] - mid[0], y = p[1] - mid[1], z = p[2] - mid[2];
    const u = cy * x - sy * y, w = sy * x + cy * y;          // turn about z (up)
    const v = cp * z - sp * w, d = sp * z + cp * w;          // tilt
    pts.push([cv.width / 2 + s * u, cv.height / 2 - s * v, d, L.colour, L.size, L.alpha]);
  }
  pts.sort((a, b) => b[2] - a[2]);                            // far first
  for (const q of pts) { g.globalAlpha = q[5]; g.fillStyle = q[3]; g.fillRect(q[0] - q[4] / 2, q[1] - q[4] / 2, q[4], q[4]); }
  g.globalAlpha = 1;
}
cv.onmousedown = e => { drag = [e.clientX, e.clientY]; };
window.onmouseup = () => { drag = null; };
window.onmousemove = e => { if (!drag) return;
  yaw += (e.clientX - drag[0]) * 0.01; pitch += (e.clientY - drag[1]) * 0.01;
  pitch = Math.max(-1.5, Math.min(1.5, pitch)); drag = [e.clientX, e.clientY]; draw(); };
cv.onwheel = e => { e.preventDefault(); zoom *= e.deltaY < 0 ? 1.1 : 1 / 1.1; draw(); };
document.getElementById("key").innerHTML = layers.slice().reverse().map(L =>
  '<span style="background:' + L.colour + '"></span>' + L.label).join("");
draw();
</script></body></html>
"""


def scene_html(scene, layers):
    import html
    data = [{"label": label, "colour": colour, "size": max(2, round(size)), "alpha": alpha,
             "points": np.round(pts, 4).tolist()} for label, pts, colour, size, alpha in layers]
    best = answer_name(scene)
    title = html.escape("%s: named %s" % (scene["label"], best))
    # The data inside a <script>: no "</" may close it early.
    return SCENE_VIEWER % {"title": title, "layers": json.dumps(data).replace("</", "<\\/")}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("report", help="report JSON (touchstone report RUN.h5 --json), or scenes.json")
    parser.add_argument("--out", required=True, help="folder for the PNG files")
    parser.add_argument("--list", help="write the paths of the files written here, one a line")
    args = parser.parse_args()
    with open(args.report) as f:
        report = json.load(f)
    os.makedirs(args.out, exist_ok=True)
    if "scenes" in report:   # touchstone recognize --scene
        written = []
        for scene in report["scenes"]:
            plot_scene(scene, args.out, written)
        if args.list:
            with open(args.list, "w") as f:
                f.write("\n".join(written) + "\n")
        return 0
    if not report.get("per_step") and "variants" not in report:
        print("touchstone_plots: the report has no completed runs", file=sys.stderr)
        return 1
    written = []
    plot_recognition(report, args.out, written)
    plot_errors(report, args.out, written)
    plot_time(report, args.out, written)
    plot_error_vs_time(report, args.out, written)
    plot_per_object(report, args.out, written)
    plot_reliability(report, args.out, written)
    if args.list:
        with open(args.list, "w") as f:
            f.write("\n".join(written) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
