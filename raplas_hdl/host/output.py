"""A finished render written and read: PNG images, the ids file, the comparison of two
renders and the summary the commands print (:func:`raplas_hdl.host.render.render` makes the
:class:`~raplas_hdl.host.render.RenderResult`)."""

from __future__ import annotations

import math

import numpy as np

from .render import RenderResult

__all__ = ["compare", "difference_image", "format_summary", "save_ids", "save_png",
           "to_uint8"]


def to_uint8(image: np.ndarray, gamma: float = 2.2) -> np.ndarray:
    """Linear colour to 8-bit sRGB-ish (clip, gamma)."""
    return np.round(255.0 * np.clip(image, 0.0, 1.0) ** (1.0 / gamma)).astype(np.uint8)


def save_png(image: np.ndarray, path, linear: bool = True):
    """Write an image (float linear colour, or uint8) as PNG with Pillow."""
    from PIL import Image      # lazy: Pillow loads only to write an image

    arr = to_uint8(image) if linear and image.dtype != np.uint8 else image
    Image.fromarray(arr).save(path)


def save_ids(result: RenderResult, path):
    """Per-pixel nearest triangle IDs (-1: none), distances, visibility and the secondary
    rays' layers (:attr:`RenderResult.layers`) as ``.npz``."""
    np.savez_compressed(path, tri_id=result.tri_id, t=result.t, visibility=result.visibility,
                        **result.layers)


def difference_image(a: RenderResult, b: RenderResult, gain: float = 4.0) -> np.ndarray:
    """``|a - b|`` of the 8-bit images times ``gain``, with pixels whose nearest triangle
    differs marked magenta (uint8)."""
    d = np.abs(to_uint8(a.image).astype(np.int16) - to_uint8(b.image).astype(np.int16))
    out = np.clip(d * gain, 0, 255).astype(np.uint8)
    out[a.tri_id != b.tri_id] = (255, 0, 255)
    return out


def compare(result: RenderResult, reference: RenderResult) -> dict:
    """Image error of ``result`` against ``reference`` (same size).

    Returns
    -------
    dict
        ``psnr`` (dB, on 8-bit images; ``inf`` when equal), ``max_abs`` (8-bit levels),
        ``tri_differs`` (fraction of pixels whose nearest triangle differs),
        ``hit_differs`` (fraction where one hits and the other does not), and ``layers``
        for the secondary rays both renders have (:attr:`RenderResult.layers`):
        ``reflection_tri`` and ``refraction_tri`` as ``{"pixels", "differs"}`` (pixels where
        either has such a ray, and the fraction of them whose nearest triangle differs),
        ``glossy_hit`` and ``ao`` as ``{"pixels", "mean_abs"}`` (pixels where both have a
        value, their mean absolute difference).
    """
    if result.image.shape != reference.image.shape:
        raise ValueError(f"image sizes differ: {result.image.shape} and "
                         f"{reference.image.shape}")
    a = to_uint8(result.image).astype(np.float64)
    b = to_uint8(reference.image).astype(np.float64)
    mse = float(np.mean((a - b) ** 2))
    psnr = math.inf if mse == 0 else 10.0 * math.log10(255.0 ** 2 / mse)
    layers = {}
    for key in ("reflection_tri", "refraction_tri"):
        if key in result.layers and key in reference.layers:
            x, y = result.layers[key], reference.layers[key]
            some = (x != -2) | (y != -2)
            layers[key] = {"pixels": int(some.sum()),
                           "differs": float(np.mean(x[some] != y[some])) if some.any() else 0.0}
    for key in ("glossy_hit", "ao"):
        if key in result.layers and key in reference.layers:
            x, y = result.layers[key], reference.layers[key]
            both = ~np.isnan(x) & ~np.isnan(y)
            layers[key] = {"pixels": int(both.sum()), "mean_abs": float(
                np.mean(np.abs(x[both] - y[both]))) if both.any() else 0.0}
    return {"psnr": psnr, "max_abs": float(np.max(np.abs(a - b))),
            "tri_differs": float(np.mean(result.tri_id != reference.tri_id)),
            "hit_differs": float(np.mean((result.tri_id >= 0) != (reference.tri_id >= 0))),
            "layers": layers}


def format_summary(result: RenderResult, comparison: dict | None = None) -> str:
    """A human-readable summary of a render."""
    st, tm = result.stats, result.timings
    bf = st["brute_force_pairs"]
    skipped = ", ".join(f"{k} {v}" for k, v in st["skipped_triangles"].items() if v) or "none"
    lines = [
        (f"scene {st['scene']} ({st['triangles']} triangles, skipped: {skipped}), "
        f"{st['size']}, backend {st['backend']}"),
        (f"  rays      {st['rays']:>12,}  (primary {st['primary_rays']:,}, shadow "
        f"{st['shadow_rays']:,})"),
        (f"  bundles   {st['bundles']:>12,}  (primary {st['primary_bundles']:,}, shadow "
        f"{st['shadow_bundles']:,}; unguaranteed {st['unguaranteed_bundles']:,})"),
        (f"  spheres   {st['spheres']:>12,}  leaf spheres of <= tris/sphere, {st['levels']} "
        f"levels; runs tested {st['unit'].get('spheres', 0):,} leaf spheres"),
        (f"  plane tests {st['plane_tests']:>10,}  (host hierarchy {st['host_plane_tests']:,}, "
        f"unit {st['unit'].get('plane_tests', 0):,})"),
        (f"  pairs     {st['pairs_issued']:>12,}  of {bf:,} brute force "
        f"({100.0 * st['pair_fraction']:.3f} %); early-out skipped "
        f"{st['early_out_pairs_skipped']:,} pairs and {st['shadow_spheres_skipped']:,} "
        f"sphere runs"),
        f"  hits      {st['hits']:>12,}  pixels hit {st['pixels_hit']:,}",
        *(f"  {kind:<10} {t['rays']:>11,} rays in {t['bundles']:,} bundles, pairs "
          f"{t['pairs_issued']:,} of {t['brute_force_pairs']:,} brute force "
          f"({100.0 * t['pair_fraction']:.3f} %), hits {t['hits']:,}, plane tests "
          f"{t['plane_tests']:,}, early-out skipped {t['early_out_pairs_skipped']:,} pairs"
          for kind, t in st.get("ray_types", {}).items()),
        (f"  events    overflow {st['events']['overflow']:,}, underflow "
        f"{st['events']['underflow']:,}, invalid {st['events']['invalid']:,} (operations)"),
    ]
    if "certified" in st:
        c = st["certified"]
        lines.append(f"  certified uncertain {c['uncertain']:,} pairs "
                     f"({100.0 * c['uncertain_fraction']:.3f} % of issued), certified hits "
                     f"{c['certified_hits']:,}; float64 filter {c['filtered']:,} pairs, "
                     f"exact {c['exact']:,} pairs in {c['exact_s']:.3f}s")
    if "output_beats" in st:
        b = st["output_beats"]
        lines.append(f"  reduction {b['answer']:,} answer beats left the unit instead of "
                     f"{b['result']:,} result beats "
                     f"({100.0 * (1 - b['answer'] / max(b['result'], 1)):.1f} % saved)")
    if "points_behind_light" in st:
        lines.append(f"  shading points without a shadow bundle: behind the light "
                     f"{st['points_behind_light']:,}, facing away {st['points_facing_away']:,}")
    h = st["hierarchy"]
    lvl = ", ".join(f"L{k}: {d}/{t} nodes ({tr:,} tris)" for k, (t, d, tr) in
                    enumerate(zip(h["tested"], h["dropped"], h["triangles_dropped"])) if t)
    lines.append(f"  hierarchy dropped {lvl}")
    lines.append("  time      " + ", ".join(f"{k} {v:.2f}s" for k, v in tm.items())
                 + f"; total {sum(tm.values()):.2f}s")
    if comparison:
        lines.append(f"  vs float64: PSNR {comparison['psnr']:.2f} dB, max diff "
                     f"{comparison['max_abs']:.0f}/255, nearest triangle differs on "
                     f"{100 * comparison['tri_differs']:.3f} % of pixels, hit/miss differs on "
                     f"{100 * comparison['hit_differs']:.3f} %")
        for key, v in comparison.get("layers", {}).items():
            if "differs" in v:
                lines.append(f"    {key}: nearest triangle differs on "
                             f"{100 * v['differs']:.3f} % of {v['pixels']:,} pixels")
            else:
                lines.append(f"    {key}: mean absolute difference {v['mean_abs']:.4f} over "
                             f"{v['pixels']:,} pixels")
    return "\n".join(lines)
