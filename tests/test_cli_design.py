"""``nlosplan design`` and its studies on the command line: errors are one line with exit code 2."""

import pytest

from nlosplan.cli import main


@pytest.mark.parametrize("argv, words", [
    (["design", "--requirement", "speed<=3"], "must look like loc<=0.05"),
    (["design", "--requirement", "shape>=2"], "in (0, 1]"),
    (["design", "--seeds", "0"], "0 is out of range"),
    (["design", "--workers", "0"], "0 is out of range"),
    (["design", "--quick", "--config", "/nonexistent/space.toml"], "does not exist"),
    (["design", "--quick", "--real", "/nonexistent/store.sqlite"], "capture store /nonexistent/store.sqlite does not exist"),
    (["study", "resolution", "--requirement", "loc"], "must look like"),
    (["design", "--cluster", "localhost:8786"], "give tcp://HOST:PORT"),
    (["design", "--cluster", "local:0"], "local:N (N >= 1)"),
    (["design", "--seed", "-1"], "argument --seed: -1 is out of range"),
    (["design", "--seed", "1000001"], "argument --seed: 1000001 is out of range"),
    (["design", "--seed", "two"], "argument --seed: 'two' is not an integer"),
    (["design", "--worlds", "0"], "argument --worlds: 0 is out of range"),
    (["design", "--models", "mlp,resnet"], "argument --models: unknown model(s) 'resnet'"),
    (["design", "--requirement", "loc>=0.03"], "loc's loc_rmse is an error (smaller is better); write loc<=0.03"),
    (["design", "--requirement", "size<=0.9"], "size's top1_acc is an accuracy (larger is better)"),
])
def test_bad_inputs_exit_2_with_one_line(capsys, argv, words):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) >= 1 and words in err[-1] and "Traceback" not in "\n".join(err)


def test_bad_config_table_and_cluster_exit_2(capsys, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[space]\nzones = ['3x3']\naxes = ['speed']\n")
    assert main(["design", "--quick", "--config", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "unknown design axis speed" in capsys.readouterr().err
    bad.write_text("[space\n")
    assert main(["design", "--quick", "--config", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "is not valid TOML" in capsys.readouterr().err


@pytest.mark.parametrize("toml, words", [
    ("[worlds]\ncount = 0\n", "[worlds] count=0 must be a whole number >= 1"),
    ("[worlds.ranges]\nalbedo = {low = 0.7, high = 0.3}\n", "[worlds.ranges] albedo: low 0.7 > high 0.3"),
    ("[worlds.ranges]\nalbedo = {low = 0.5, high = 1.5}\n", "albedo: 0.5..1.5 leaves the physical range [0, 1]"),
    ("[worlds.ranges]\nspeed = {low = 1, high = 2}\n", "[worlds.ranges] speed: unknown world parameter"),
    ("[worlds]\nplanets = 3\n", "unknown [worlds] key(s) planets; allowed: budget, candidates, count"),
    ("[worlds]\nbudget = -2\n", "[worlds] budget=-2 must be a whole number >= 0"),
    ("[worlds]\nbudget = 2.5\n", "[worlds] budget=2.5 must be a whole number >= 0"),
    ("[search]\nseed = -3\n", "seed=-3 must be a whole number from 0 to 1000000"),
    ("[search]\nmodels = ['mlp', 'gpt']\n", "unknown model(s) 'gpt'"),
])
def test_bad_worlds_and_search_tables_exit_2_naming_the_key(capsys, tmp_path, toml, words):
    bad = tmp_path / "bad.toml"
    bad.write_text(toml)
    assert main(["design", "--quick", "--config", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0] and str(bad) in err[0]


def test_seed_limit_of_the_cli_is_the_search_s():
    from nlosplan.cli.design import MAX_DESIGN_SEED
    from nlosplan.planner.design.search import MAX_SEED as SEARCH_MAX
    from nlosplan.resources import MAX_DESIGN_SEED as DEFINED

    assert MAX_DESIGN_SEED is DEFINED and SEARCH_MAX is DEFINED


def test_the_largest_seed_gives_evaluation_seeds_the_split_and_training_accept():
    """Evaluation seeds (seed x 1000 + i) stay within scikit-learn's random_state range at --seed's limit."""
    import numpy as np
    from sklearn.model_selection import train_test_split

    from nlosplan.planner.design.search import MAX_SEED, SEED_STRIDE, SearchConfig

    cfg = SearchConfig(seed=MAX_SEED, max_seeds=SEED_STRIDE // 10)
    top = cfg.seed_of(cfg.max_seeds - 1)
    assert top < 2**32
    tr, te = train_test_split(np.arange(10), test_size=0.3, random_state=top)
    assert len(tr) == 7 and len(te) == 3


def test_seed_models_and_worlds_reach_the_configuration():
    from nlosplan.cli import build_parser
    from nlosplan.cli.design import build_config

    args = build_parser().parse_args(["design", "--quick", "--seed", "7", "--models", "cnn1d,mlp", "--worlds", "3"])
    cfg = build_config(args)
    assert cfg.search.seed == 7 and cfg.search.models == ("cnn1d", "mlp") and cfg.worlds.count == 3
    assert cfg.hash() != build_config(build_parser().parse_args(["design", "--quick"])).hash()


def test_help_teaches_with_examples(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["design", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "nlosplan design --quick --json" in out and "--resume" in out and "--cluster" in out
    assert "least sensor hardware" in out
    assert "--seed" in out and "--models" in out and "--worlds" in out
    assert "sqrt of the mean of the squared" in out and "undecided" in out
    assert "DENALI's own design point" in out and '"denali_point"' in out and "4.56 cm" in out
