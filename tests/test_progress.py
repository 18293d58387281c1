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
