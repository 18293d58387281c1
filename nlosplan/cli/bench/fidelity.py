"""``nlosplan bench fidelity`` (error against run time of both simulators) and ``bench crossval``."""

from __future__ import annotations

import argparse

from nlosplan.cli.common import emit, int_type, note, progress_bar
from nlosplan.cli.selections import choice_list, object_list

FIDELITY_DESCRIPTION = """\
Error against run time of both simulators on DENALI 3x3 (Lambertian objects
A_8in at position 19, circle_4in at 73, 3_4in at 47, minus_8in at 99): every
fidelity level of the fast backend and of the Mitsuba twin, seconds per scene
and the relative L1 error of the three-bounce histogram against a converged
twin reference (its own error is measured from two independent halves and
printed), and the speed-up of the fast backend over the twin at equal error. About 2 minutes on 2 cores.
JSON: {"rows": [{"backend", "fidelity", "seconds", "rel_l1_error"}...],
"speedup_at_equal_error": number, "speedups", "reference", "config"}."""

CROSSVAL_DESCRIPTION = """\
Cross-validation of the twin against the fast backend on the DENALI rig: every
reflectance model x object x size x position, normalized relative L1 of the
three-bounce histogram (target <= 5 %) and centroid shift (target <= 0.5 bin,
zones with >= 5 % of the signal). Models: lambertian (albedo 0.5), mixed (a
2 deg retroreflective lobe of 0.4 on a Lambertian base of 0.4), mount (a
Lambertian object with the mount and plate, 0.8, in the signal). About 2
minutes per model for 60 cases on 2 cores. JSON: {"cases": [{"model",
"object", "size", "position", "rel_l1", "centroid_shift_bins", "total_ratio",
...}...], "summary": {...}, "config": {...}}."""


def _cmd_fidelity(args) -> int:
    from nlosplan.files import check_plot_path
    from nlosplan.simulators.bench import FAST_LEVELS, TWIN_LEVELS, bench_fidelity, format_bench_fidelity

    if args.plot:
        check_plot_path(args.plot, "--plot")

    note(args, "bench fidelity: reference twin, then every level of both backends ...")
    with progress_bar(args, 1 + len(FAST_LEVELS) + len(TWIN_LEVELS), "bench fidelity", "step") as bar:
        def progress(text):
            bar.update(1, text[:60])

        result = bench_fidelity(reference_spp=args.reference_spp, seed=args.seed, progress=progress)
    text = format_bench_fidelity(result)
    if args.plot:
        from nlosplan.reports.fidelity_plot import plot_fidelity

        path = plot_fidelity(result["rows"], args.plot, reference_self_error=result["reference"]["rel_l1_self_error"],
                             title="fast backend vs Mitsuba twin: DENALI 3x3, Lambertian objects")
        result["plot"] = str(path)
        text += f"\nplot: {path}"
    emit(args, result, text)
    return 0


def _cmd_crossval(args) -> int:
    from nlosplan.simulators.bench import check_models, cross_validate, format_table

    models = check_models(m.strip() for m in args.models.split(",") if m.strip())
    objects, sizes = args.objects, args.sizes
    positions = range(0, 100, 100 // args.positions)[: args.positions]
    n = len(models) * len(objects) * len(sizes) * len(positions)
    with progress_bar(args, n, "bench crossval", "case") as bar:
        def progress(text):
            bar.update(1, text[:60])

        result = cross_validate(objects, sizes, positions, models=models,
                                twin_fidelity={"spp": args.spp, "zone_sub": 8}, seed=args.seed, progress=progress)
    emit(args, result, format_table(result))
    return 0 if result["summary"]["passed"] == result["summary"]["cases"] else 1


def _parser(bsub, name, help_text, description, example):
    return bsub.add_parser(name, help=help_text, description=description, epilog=f"example:\n  {example}",
                           formatter_class=argparse.RawDescriptionHelpFormatter)


def add_bench(bsub) -> None:
    """``bench fidelity`` and ``bench crossval``."""
    p = _parser(bsub, "fidelity", "error against run time of the fast backend and the Mitsuba twin, and the "
                "speed-up at equal error", FIDELITY_DESCRIPTION,
                "nlosplan bench fidelity --json --plot out/fidelity.png")
    p.add_argument("--reference-spp", type=int_type(256, 1 << 20), default=32768,
                   help="samples per pixel of the twin reference (default: %(default)s)")
    p.add_argument("--seed", type=int_type(0, 2**31), default=0, help="twin seed (default: 0)")
    p.add_argument("--plot", default="", metavar="PATH", help="also plot error against run time to PATH (.png, ...; "
                                                             "default: none)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=_cmd_fidelity)
    c = _parser(bsub, "crossval", "cross-validate the Mitsuba twin against the fast backend (DENALI: Lambertian, "
                "mixed reflectance, mount)", CROSSVAL_DESCRIPTION,
                "nlosplan bench crossval --models lambertian,mixed,mount --objects A,circle,3 --positions 10 --json")
    c.add_argument("--models", default="lambertian,mixed,mount",
                   help="reflectance models, comma-separated: lambertian, mixed, mount (default: %(default)s)")
    c.add_argument("--objects", type=object_list, default=["A", "circle", "3"], metavar="A,S,...",
                   help="DENALI objects (default: A,circle,3)")
    c.add_argument("--sizes", type=choice_list(("4in", "8in")), default=["4in", "8in"], metavar="4in,8in",
                   help="sizes (default: 4in,8in)")
    c.add_argument("--positions", type=int_type(1, 100), default=10,
                   help="gantry positions, evenly spaced over 0..99 (default: %(default)s)")
    c.add_argument("--spp", type=int_type(16, 1 << 20), default=4096, help="twin samples per pixel (default: 4096)")
    c.add_argument("--seed", type=int_type(0, 2**31), default=0, help="twin seed (default: 0)")
    c.add_argument("--json", action="store_true", help="machine-readable output")
    c.set_defaults(func=_cmd_crossval)
