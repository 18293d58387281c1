"""Text report of ``nlosplan bench simulate``: the error-against-run-time table and the verdict."""

from __future__ import annotations

import math

import numpy as np

from nlosplan.reports.tables import format_table


def _pct(v: float) -> str:
    return "n/a" if not math.isfinite(v) else f"{100 * v:.3g} %"


def verdict(result: dict) -> str:
    """One line: which levels meet the target error at the target rate (batched), and the stretch rate.

    The targets are read from ``result["config"]`` (``target_rel_l1``,
    ``target_scenes_per_second``, ``stretch_scenes_per_second``).
    """
    rows, cfg = result["levels"], result["config"]
    err, rate, stretch_rate = cfg["target_rel_l1"], cfg["target_scenes_per_second"], cfg["stretch_scenes_per_second"]
    ok = [r["fidelity"] for r in rows if r["rel_l1_error"] <= err and r["scenes_per_second"] >= rate]
    stretch = [r["fidelity"] for r in rows if r["rel_l1_error"] <= err and r["scenes_per_second"] >= stretch_rate]
    what = f"{cfg['zones']}x{cfg['n_bins']}"
    line = (f"target (<= {100 * err:g} % rel. L1 at >= {rate:g} {what} histograms/s batched): "
            f"{'met by ' + ', '.join(ok) if ok else 'met by no level'}; stretch (>= {stretch_rate:g}/s): "
            f"{'met by ' + ', '.join(stretch) if stretch else 'met by no level'}")
    self_err = result["reference"]["reference_self_error"]
    if self_err > 0.25 * err:
        line += f" (caution: the reference's own error, {_pct(self_err)}, is not far below the target)"
    return line


def format_bench_simulate(result: dict) -> str:
    """Text report: the error-against-run-time table, pruning, arithmetic limit and the verdict."""
    table = [{
        "fidelity": r["fidelity"],
        "paths/scene": f"{r['paths_per_scene']:,}",
        "single ms": 1e3 * r["seconds_single"],
        "batched ms/scene": 1e3 * r["seconds_per_scene_batched"],
        "scenes/s": r["scenes_per_second"],
        "compile s": r["compile_seconds"],
        "rel L1 %": 100 * r["rel_l1_error"],
        "centroid shift bins": r["centroid_shift_bins"],
    } for r in result["levels"]]
    cfg, ref, pr, ar, mc = (result[k] for k in ("config", "reference", "pruning", "arithmetic", "machine"))
    refs = ", ".join(f"{p} ({cfg['scenes'][str(p)]})" for p in cfg["reference_positions"])
    lines = [
        f"fast simulator, DENALI {', '.join(cfg['objects'])} x {', '.join(cfg['sizes'])} ({cfg['sensor']}, "
        f"{cfg['zones']}x{cfg['n_bins']}, "
        f"lights {cfg['lights']}, {cfg['dtype']}): batched over {len(cfg['positions'])} positions, single at "
        f"position {cfg['single_position']}; error of the three-bounce histogram against the reference at positions "
        f"{refs} (worst one)",
        "",
        format_table(table, floatfmt="{:.4g}"),
        "",
        f"reference: float64, {_knobs(ref['knobs'])}; {np.mean(ref['seconds_per_scene']):.3g} s per scene "
        f"(incl. plan and compile), {int(np.mean(ref['paths_per_scene'])):,} paths; its own error (against half the "
        f"object samples): rel L1 {_pct(ref['reference_self_error'])}, centroid "
        f"{ref['reference_self_centroid_shift_bins']:.3g} bins",
        f"pruning ({pr['level']}, batched over {pr['positions']} positions, per scene): pruned "
        f"{1e3 * pr['prune_seconds']:.3g} ms ({pr['paths_pruned']:,} paths) vs prune=False "
        f"{1e3 * pr['no_prune_seconds']:.3g} ms ({pr['paths_full']:,} paths): x{pr['prune_speedup']:.2f}; "
        f"pruned = full within {pr['pruned_vs_full_max_rel_diff_counts']:.2g} (counts) and "
        f"{pr['pruned_vs_full_max_rel_diff_object']:.2g} (object part), max |diff| / max",
        f"  centre zone {tuple(pr['centre_zone'])} only {1e3 * pr['centre_zone_seconds']:.3g} ms "
        f"({pr['paths_centre_zone']:,} paths) vs all zones {1e3 * pr['all_zones_seconds']:.3g} ms: "
        f"x{pr['centre_zone_speedup']:.2f} (same centre zone within {pr['centre_vs_all_max_rel_diff']:.2g}); "
        f"lights off {1e3 * pr['lights_off_seconds']:.3g} ms vs on {1e3 * pr['lights_on_seconds']:.3g} ms: "
        f"x{pr['lights_off_speedup']:.2f}",
        _arith_line(ar),
        *_model_lines(result.get("models", [])),
        f"machine: {', '.join(mc['jax_devices'])}; {mc['cpu_count']} CPU cores ({mc['processor']}); jax {mc['jax']}, "
        f"numpy {mc['numpy']}; load average {mc['load_average_start']} at start, {mc.get('load_average_end')} at end",
        _deposit_line(cfg),
        verdict(result),
    ]
    return "\n".join(lines)


def _deposit_line(cfg: dict) -> str:
    """Which deposit the timed levels used (the compiled kernels, or why not) and on how many threads."""
    kernel = cfg.get("kernels", cfg.get("deposit_kernel"))  # the key of results written before the sum-convolution
    threads = f"; chunks on {cfg['threads']} thread(s)" if "threads" in cfg else ""
    if kernel is None:  # a result written before the kernel
        return f"deposit: {cfg.get('deposit', 'window')}{threads}"
    if kernel["available"]:
        return f"deposit: {cfg['deposit']} (the compiled kernels, {kernel['why']}){threads}"
    return f"deposit: {cfg['deposit']} (the compiled kernels are not available: {kernel['why']}){threads}"


def _model_lines(rows: list) -> list[str]:
    """One line per scene model of ``bench simulate`` (timed back to back at the study level)."""
    out = []
    for r in rows:
        opts = ", ".join(f"{k}={v}" for k, v in r["options"].items()) or "the preset's defaults"
        out.append(f"model {r['model']} ({opts}; {r['level']}, batched): {r['scenes_per_second']:.4g} scenes/s "
                   f"(x{r['speed_ratio_vs_retroreflective']:.2f} of retroreflective in the same run), "
                   f"{r['paths_per_scene']:,} paths, rel L1 {_pct(r['rel_l1_error'])}, centroid "
                   f"{r['centroid_shift_bins']:.3g} bins")
        lay = r.get("layout")
        if lay:
            out.append(f"  as DENALI's captures come ({lay['objects_and_sizes']} objects and sizes at each of "
                       f"{lay['positions']} positions, the mount computed once per position): "
                       f"{lay['scenes_per_second']:.4g} scenes/s")
        b = r.get("baseline")
        if b:
            out.append(f"  vs the path before issue 20 ({b['deposit']} deposit, chunks gathered per call, same run): "
                       f"{b['scenes_per_second']:.4g} "
                       f"scenes/s (new x{r['speed_ratio_vs_baseline']:.2f}), single call {r['single_call_ms']:.3g} ms "
                       f"vs {b['single_call_ms']:.3g} ms (x{r['single_call_ratio_vs_baseline']:.2f}), rel L1 "
                       f"{_pct(r['rel_l1_error'])} vs {_pct(b['rel_l1_error'])}, new vs old max rel diff "
                       f"{b['max_rel_diff_vs_new']:.2g}")
    return out


def _knobs(k: dict) -> str:
    return ", ".join(f"{a}={b}" for a, b in k.items() if a != "seed")


def _arith_line(ar: dict) -> str:
    b = ar["flops_breakdown"]
    parts = ", ".join(f"{k.replace('_', ' ')} {v / 1e6:.3g}" for k, v in b.items() if v > 0)
    xla = ar["xla_cost_analysis"]
    xla_txt = (f"; XLA counts {xla['flops'] / 1e6:.3g} MFLOP + {xla['transcendentals'] / 1e6:.3g} M transcendentals "
               f"({ar['achieved_gflops_xla_count']:.3g} GFLOP/s)" if xla.get("available") else "")
    pk = ar["matmul_peak"]
    return (f"arithmetic ({ar['level']}): {ar['flops_per_scene'] / 1e6:.3g} MFLOP per scene ({parts} MFLOP; "
            f"{ar['paths_per_scene']:,} paths x {sum(ar['flops_per_path'][k] for k in ('far_coupling', 'weight_and_time', 'deposit'))} "
            f"flops) in {1e3 * ar['seconds_per_scene']:.3g} ms = {ar['achieved_gflops']:.3g} GFLOP/s{xla_txt}; "
            f"{pk['dtype']} matmul {pk['n']}^2 in this process: {pk['gflops']:.3g} GFLOP/s; "
            f"fraction of that peak {100 * ar['fraction_of_peak']:.2g} %")
