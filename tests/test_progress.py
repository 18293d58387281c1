"""Progress lines off a terminal: a stage that counts another unit starts its counts afresh and names them."""
import io

from nlosplan.progress import Progress


def test_a_stage_of_another_unit_names_it_and_restarts_its_counts():
    buf = io.StringIO()
    with Progress("design", None, "evaluation", stream=buf, tty=False, every=0) as p:
        p.stage("references", unit="reference")
        p.set(1, 5, "1x1")
        p.stage("screen", unit="evaluation")
        p.set(3, 10, "x")
    lines = buf.getvalue().splitlines()
    assert "[references]: 1/5 references (20 %)" in lines[1]
    assert "[screen]: 0 evaluations" in lines[2]          # not the references' 1/5
    assert "[screen]: 3/10 evaluations (30 %)" in lines[3]
    assert lines[-1].startswith("nlosplan design [screen]: done, 3/10 evaluations")


def test_the_time_left_counts_from_the_stage_not_the_run(monkeypatch):
    """A stage that starts 1,000 s into a run and takes 10 s per unit says 10 s per unit left, not the run's pace."""
    import nlosplan.progress as progress

    clock = [0.0]
    monkeypatch.setattr(progress.time, "monotonic", lambda: clock[0])
    buf = io.StringIO()
    p = Progress("design", None, "evaluation", stream=buf, tty=False, every=0)
    p.stage("worlds", unit="evaluation")
    p.set(400, 441)
    clock[0] = 1000.0
    p.stage("world references", unit="reference")
    p.set(0, 18)
    clock[0] = 1010.0
    p.set(1, 18)
    assert buf.getvalue().splitlines()[-1].endswith("1/18 references (6 %), 1010 s, about 170 s left")
    clock[0] = 1030.0
    p.set(3, 18)
    assert "about 150 s left" in buf.getvalue().splitlines()[-1]
    clock[0] = 1040.0
    p.set(0, 18)     # the counts start over within the stage
    clock[0] = 1045.0
    p.set(1, 18)
    assert "about 85 s left" in buf.getvalue().splitlines()[-1]
