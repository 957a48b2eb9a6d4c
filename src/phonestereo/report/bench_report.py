"""The HTML report of a thesis-bench run (``phonestereo demo`` / ``evaluate --report``).

One self-contained HTML file (figures embedded as PNG data URIs, so it can be mailed or opened
from anywhere): the stage table, the error against distance per stage beside the Cramér–Rao
floor, rendered captures with their ROIs, the learned correction over the sensor, and — when
the bench ran them — the ablation table.
"""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from phonestereo.flows.config import FlowConfig
from phonestereo.flows.config_file import flow_config_from_dict
from phonestereo.flows.corrector import Corrector
from phonestereo.flows.roi_disparity import reference_rectification
from phonestereo.io import load_calibration, load_capture_set, read_gray

STAGES = (("naive", "naive Z = f·B/d"), ("measured", "fixes, no learned correction"),
          ("full", "full flow"), ("cramer_rao_floor", "matching σ (Cramér–Rao)"))


def _png(fig: Figure) -> str:
    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def error_vs_distance_figure(bench: dict[str, Any]) -> Figure:
    """Median relative error per distance for every stage (log scale), p90 as whiskers."""
    fig = Figure(figsize=(7.5, 4.2))
    ax = fig.add_subplot(1, 1, 1)
    rows = bench["per_distance"]
    x = np.array([r["distance_m"] for r in rows])
    for key, label in STAGES:
        med = np.array([np.nan if not r.get(key) or r[key]["median_rel_err"] is None
                        else 100 * r[key]["median_rel_err"] for r in rows])
        p90 = np.array([np.nan if not r.get(key) or r[key]["p90_rel_err"] is None
                        else 100 * r[key]["p90_rel_err"] for r in rows])
        style = "--" if key == "cramer_rao_floor" else "-"
        line = ax.plot(x, med, style, marker="o", label=label)[0]
        ax.vlines(x, med, p90, color=line.get_color(), alpha=0.4)
    ax.axhline(1.0, color="k", lw=0.8, ls=":", label="1 % target")
    ax.set_yscale("log")
    ax.set_xlabel("distance (m)")
    ax.set_ylabel("|relative depth error| (%)  median, bar to p90")
    ax.set_title("Depth error per distance and stage")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def captures_figure(capture_set: Path, ids: list[str]) -> Figure:
    """Wide images of some captures (downsampled) with their ROI drawn."""
    cs = load_capture_set(capture_set)
    fig = Figure(figsize=(3.2 * len(ids), 2.9))
    for i, cid in enumerate(ids):
        ax = fig.add_subplot(1, len(ids), i + 1)
        entry = cs.get(cid)
        img = read_gray(cs.image_paths(cid)[0])[::4, ::4]
        ax.imshow(img, cmap="gray", vmin=0, vmax=255)
        if entry.roi is not None:
            x, y, w, h = (v / 4 for v in entry.roi)
            ax.add_patch(Rectangle((x, y), w, h, fill=False, ec="red", lw=1.5))
        ax.set_title(f"{cid} ({entry.kind})", fontsize=8)
        ax.set_axis_off()
    fig.suptitle("Rendered wide captures (ROI in red)", fontsize=10)
    fig.tight_layout()
    return fig


def correction_figure(
    capture_set: Path, observations: list[Any], config: FlowConfig, d_px: float | None = None
) -> Figure | None:
    """The learned correction over the sensor at one disparity, with the learned points."""
    if not observations:
        return None
    cal = load_calibration(load_capture_set(capture_set).calibration_path())
    ref = reference_rectification(cal.rig, config.mode)
    corr = Corrector.for_calibration(observations, config, cal)
    obs = corr.observations
    d = float(np.median(obs["d_measured_px"])) if d_px is None else d_px
    w, h = ref.wide_rect.size
    gx, gy = np.meshgrid(np.linspace(0, w - 1, 60), np.linspace(0, h - 1, 45))
    bucket = str(obs["orientation"][0])
    c = corr.correct(np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, d)]), bucket)
    fig = Figure(figsize=(6.5, 4.6))
    ax = fig.add_subplot(1, 1, 1)
    im = ax.imshow(c.value_px.reshape(gx.shape), extent=(0, w - 1, h - 1, 0), cmap="viridis")
    fig.colorbar(im, ax=ax, label="correction added to d (px)")
    ax.scatter(obs["x_px"], obs["y_px"], s=6, c="w", edgecolors="k", lw=0.3, label="faces")
    ax.set_xlabel("rectified x (px)")
    ax.set_ylabel("rectified y (px)")
    ax.set_title(f"Learned correction over the sensor at d = {d:.1f} px (bucket {bucket})")
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    return fig


def _pct(v: Any) -> str:
    return "–" if v is None else f"{100 * float(v):.2f} %"


def _table(bench: dict[str, Any]) -> str:
    head = "".join(f"<th>{html.escape(label)}<br>median / p90</th>" for _, label in STAGES)
    body = []
    for r in bench["per_distance"]:
        cells = "".join(
            f"<td>{_pct((r.get(k) or {}).get('median_rel_err'))} / "
            f"{_pct((r.get(k) or {}).get('p90_rel_err'))}</td>"
            for k, _ in STAGES
        )
        body.append(f"<tr><td>{r['distance_m']:.1f} m</td>{cells}</tr>")
    st = bench["stages"]
    cells = "".join(
        f"<td><b>{_pct(st[k]['median_rel_err'])} / {_pct(st[k]['p90_rel_err'])}</b></td>"
        for k, _ in STAGES
    )
    body.append(f"<tr><td><b>all</b></td>{cells}</tr>")
    return f"<table><tr><th>distance</th>{head}</tr>{''.join(body)}</table>"


def _ablation(bench: dict[str, Any]) -> str:
    rows = bench.get("ablation")
    if not rows:
        return ""
    body = "".join(
        f"<tr><td>{html.escape(r['without'])}</td><td>{_pct(r['median_rel_err'])}</td>"
        f"<td>{_pct(r['p90_rel_err'])}</td><td>{r['gated']}</td></tr>"
        for r in rows
    )
    full = bench["stages"]["full"]
    return (
        "<h2>Ablation: each fix switched the other way in turn</h2><table><tr><th>change</th>"
        "<th>median</th><th>p90</th><th>gated</th></tr>"
        f"<tr><td><i>(all fixes on)</i></td><td>{_pct(full['median_rel_err'])}</td>"
        f"<td>{_pct(full['p90_rel_err'])}</td><td>{bench['stages']['gated']}</td></tr>"
        f"{body}</table>"
    )


def write_report(bench: dict[str, Any], out: str | Path, *, title: str = "phonestereo") -> Path:
    """Write the HTML report of a :func:`~phonestereo.evaluation.bench.run_bench` result."""
    root = Path(bench["capture_set"])
    given = {k: v for k, v in bench.get("config", {}).items() if k != "mode"}
    cfg = flow_config_from_dict(given, "the bench's config") if given else FlowConfig()
    cs = load_capture_set(root)
    ver = [c.id for c in cs.captures() if c.kind == "verification"]
    faces = [c.id for c in cs.captures() if c.kind == "face"]
    pick = ([faces[0]] if faces else []) + [
        ver[i] for i in sorted({0, len(ver) // 2, len(ver) - 1})
    ]
    figs = [error_vs_distance_figure(bench), captures_figure(root, pick)]
    cf = correction_figure(root, bench.get("_observations", []), cfg)
    if cf is not None:
        figs.append(cf)
    imgs = "".join(f'<p><img alt="figure" src="{_png(f)}"></p>' for f in figs)
    st = bench["stages"]
    within = st.get("within_sigma")
    summary = (
        f"<p>{len(bench['captures'])} verification captures, "
        f"{bench['learning']['n_observations']} learned face observations. Full flow: median "
        f"{_pct(st['full']['median_rel_err'])}, p90 {_pct(st['full']['p90_rel_err'])}; "
        f"|Z − Z<sub>true</sub>| ≤ σ for {_pct(within)} of the captures.</p>"
    )
    doc = f"""<!doctype html><html><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:2em auto}}
table{{border-collapse:collapse}}td,th{{border:1px solid #bbb;padding:3px 8px;text-align:right}}
img{{max-width:100%}}</style></head><body><h1>{html.escape(title)}</h1>{summary}
<h2>Relative depth error per stage</h2>{_table(bench)}{_ablation(bench)}
<h2>Figures</h2>{imgs}</body></html>"""
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(doc, encoding="utf-8")
    return path


__all__ = ["captures_figure", "correction_figure", "error_vs_distance_figure", "write_report"]
