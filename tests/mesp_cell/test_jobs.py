"""The SQLite job store: transitions, checkpoints, concurrent access."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from core.errors import InputError
from mesp_cell.cell_client import CellClient
from mesp_cell.jobs import JobStore, check_submission
from tests.mesp_cell import synthetic


@pytest.fixture
def store(tmp_path: Path) -> JobStore:
    return JobStore(tmp_path / "jobs.sqlite")


@pytest.fixture
def model(tmp_path: Path) -> Path:
    (tmp_path / "import").mkdir(exist_ok=True)
    p = tmp_path / "import" / "My Part.stl"
    synthetic.write_cube(p)  # a real model: submit loads it
    return p


def test_lifecycle_and_history(store: JobStore, model: Path, tmp_path: Path) -> None:
    job = store.submit(model, "sim")
    assert job.id == "my-part-0001" and job.state == "submitted" and Path(job.dir).is_dir()
    for state in ("sliced", "planned", "ready_check", "printing", "interrupted", "printing",
                  "done"):
        store.transition(job.id, state)
    assert [to for _, _, to, _ in store.history(job.id)] == [
        "submitted", "sliced", "planned", "ready_check", "printing", "interrupted", "printing",
        "done"]


def test_invalid_transitions_are_refused_with_the_reason(store: JobStore, model: Path,
                                                         tmp_path: Path) -> None:
    job = store.submit(model, "sim")
    with pytest.raises(InputError, match="submitted; it can become only"):
        store.transition(job.id, "printing")
    store.transition(job.id, "aborted")
    with pytest.raises(InputError, match="finished job cannot become printing"):
        store.transition(job.id, "printing")
    with pytest.raises(InputError, match="only a paused or interrupted job"):
        store.request_resume(job.id)
    with pytest.raises(InputError, match="no job"):
        store.get("nope")
    with pytest.raises(InputError, match="not a job state"):
        store.transition(job.id, "flying")


def test_checkpoint_only_moves_forward_and_resume_flag(store: JobStore, model: Path,
                                                      tmp_path: Path) -> None:
    job = store.submit(model, "sim")
    for state in ("sliced", "planned", "ready_check", "printing"):
        store.transition(job.id, state)
    store.checkpoint(job.id, 1, 30, 600)
    store.checkpoint(job.id, 0, 10, 200)  # a late, older event must not move it back
    rec = store.get(job.id)
    assert (rec.layer, rec.waypoint, rec.sample) == (1, 30, 600)
    store.transition(job.id, "paused")
    assert store.next_pending("sim") is None
    store.request_resume(job.id)
    nxt = store.next_pending("sim")
    assert nxt is not None and nxt.id == job.id and nxt.resume == 1
    assert store.next_pending("other") is None
    assert store.transition(job.id, "printing").resume == 0


def test_two_connections_see_each_other(store: JobStore, model: Path, tmp_path: Path) -> None:
    other = JobStore(store.path)
    job = store.submit(model, "sim")
    other.transition(job.id, "sliced")
    assert store.get(job.id).state == "sliced"
    with pytest.raises(InputError, match="not submitted"):
        store.transition(job.id, "failed", expect="submitted")
    second = other.submit(model, "sim")
    assert second.id != job.id
    assert [j.id for j in store.query("sim")] == [job.id, second.id]


def test_submission_checks(model: Path, tmp_path: Path) -> None:
    check_submission(model)
    with pytest.raises(InputError, match="does not exist"):
        check_submission(tmp_path / "none.stl")
    bad = tmp_path / "x.docx"
    bad.write_text("x")
    with pytest.raises(InputError, match="unsupported type"):
        check_submission(bad)
    job = tmp_path / "job.toml"
    job.write_text("[slicing\n")
    with pytest.raises(InputError, match="not valid TOML"):
        check_submission(model, job_file=job)
    job.write_text("[nonsense]\nx = 1\n")
    with pytest.raises(InputError, match="nonsense"):
        check_submission(model, job_file=job)


def test_waiting_without_progress_times_out_but_a_print_that_advances_does_not(
        model: Path, tmp_path: Path) -> None:
    client = CellClient("sim", None, tmp_path)  # store only: no cell needed to wait

    def printing() -> str:
        job = client.submit(model)
        for state in ("sliced", "planned", "ready_check", "printing"):
            client.store.transition(job.id, state)
        return job.id

    def advance(job_id: str) -> threading.Thread:
        def run() -> None:  # a checkpoint every 0.05 s for 1.2 s, then the end
            other = JobStore(tmp_path / "jobs.sqlite")
            for k in range(24):
                time.sleep(0.05)
                other.checkpoint(job_id, 0, k, 100 * (k + 1))
            other.transition(job_id, "done")
            other.close()
        worker = threading.Thread(target=run)
        worker.start()
        return worker

    stalled = printing()
    with pytest.raises(TimeoutError, match="without progress"):
        client.wait(stalled, timeout=0.5, poll_s=0.02, idle=True)
    # the same advancing print: 0.5 s in all is too short, 0.5 s without progress is not
    job_id = printing()
    worker = advance(job_id)
    with pytest.raises(TimeoutError, match="in all"):
        client.wait(job_id, timeout=0.5, poll_s=0.02)
    worker.join()
    job_id = printing()
    worker = advance(job_id)
    done = client.wait(job_id, timeout=0.5, poll_s=0.02, idle=True)
    worker.join()
    assert done.state == "done" and done.waypoint == 23
    client.close()


def test_a_fresh_print_waits_in_ready_check_until_confirmed(store: JobStore, model: Path,
                                                            tmp_path: Path) -> None:
    first = store.submit(model, "sim")
    second = store.submit(model, "sim")
    for job in (first, second):
        store.transition(job.id, "sliced")
        store.transition(job.id, "planned")
    with pytest.raises(InputError, match="planned; it can become only"):
        store.transition(first.id, "printing")  # never straight from planned
    with pytest.raises(InputError, match="only a job waiting in ready_check"):
        store.confirm_ready(first.id)
    nxt = store.next_pending("sim")
    assert nxt is not None and nxt.id == first.id
    store.transition(first.id, "ready_check")
    # one job waits for the operator at a time: the second is not parked, nothing prints
    assert store.next_pending("sim") is None
    store.confirm_ready(first.id, "test")
    nxt = store.next_pending("sim")
    assert nxt is not None and (nxt.id, nxt.state, nxt.ready) == (first.id, "ready_check", 1)
    assert store.transition(first.id, "printing").ready == 0
    assert store.history(first.id)[-2][3] == "tank confirmed ready by test"
    nxt = store.next_pending("sim")  # the first prints; the second may now wait for the tank
    assert nxt is not None and nxt.id == second.id and nxt.state == "planned"
    store.transition(second.id, "ready_check")
    store.confirm_ready(second.id)
    store.unconfirm_all("sim")  # a new session: the old confirmation does not count
    assert store.next_pending("sim") is None
    store.transition(second.id, "printing")
    store.transition(second.id, "paused")  # a paused job holds the tank: nothing else parks
    third = store.submit(model, "sim")
    store.transition(third.id, "sliced")
    store.transition(third.id, "planned")
    assert store.next_pending("sim") is None
    store.transition(second.id, "aborted")
    nxt = store.next_pending("sim")
    assert nxt is not None and nxt.id == third.id
    store.note(second.id, "a   note")
    assert store.history(second.id)[-1][1:] == ("aborted", "aborted", "a note")


def test_job_ids_are_made_by_the_store_and_stay_in_its_folder(store: JobStore,
                                                              tmp_path: Path) -> None:
    import inspect

    assert "job_id" not in inspect.signature(store.submit).parameters
    with pytest.raises(TypeError):
        store.submit(tmp_path / "a.stl", "sim", job_id="../../x")  # type: ignore[call-arg]
    (tmp_path / "import").mkdir()
    odd = tmp_path / "import" / "..%2F..%2Fx .. ; rm -rf.stl"
    synthetic.write_cube(odd)
    job = store.submit(odd, "sim")
    assert Path(job.dir).resolve().parent == (tmp_path / "jobs").resolve()
    assert all(c.isalnum() or c == "-" for c in job.id)


def test_submission_refuses_what_the_slicer_cannot_read(tmp_path: Path) -> None:
    import os

    for name, body in (("a.off", b"OFF\n"), ("a.3mf", b"PK"), ("a.mesh", b"Mesh"),
                       ("a.vtu", b"<?xml \x00\xff")):
        (tmp_path / name).write_bytes(body)
        with pytest.raises(InputError):
            check_submission(tmp_path / name)
    os.symlink("/etc/shadow", tmp_path / "shadow.stl")
    with pytest.raises(InputError, match="outside its folder"):
        check_submission(tmp_path / "shadow.stl")


def test_models_are_copied_from_an_import_folder_only(store: JobStore, model: Path,
                                                      tmp_path: Path) -> None:
    import os
    import stat

    job = store.submit(model, "sim")
    copy = Path(job.model)
    assert copy.parent == Path(job.dir) and copy.read_bytes() == model.read_bytes()
    model.write_bytes(b"changed after submission")  # the job keeps its own copy
    assert copy.read_bytes() != model.read_bytes()
    outside = tmp_path / "elsewhere.stl"
    synthetic.write_cube(outside)
    with pytest.raises(InputError, match="not in an import folder"):
        store.submit(outside, "sim")
    os.symlink("/etc/shadow", tmp_path / "import" / "shadow.stl")
    with pytest.raises(InputError, match="outside the import folder"):
        store.submit(tmp_path / "import" / "shadow.stl", "sim")
    os.symlink(outside, tmp_path / "import" / "out.stl")
    with pytest.raises(InputError, match="outside the import folder"):
        store.submit(tmp_path / "import" / "out.stl", "sim")
    for path in (store.path, copy):
        assert stat.S_IMODE(path.stat().st_mode) == 0o600, path
    for path in (store.path.parent, Path(job.dir)):
        assert stat.S_IMODE(path.stat().st_mode) == 0o700, path


def test_the_client_imports_the_operators_files(model: Path, tmp_path: Path) -> None:
    import os

    client = CellClient("sim", None, tmp_path / "home")
    outside = tmp_path / "part.stl"
    synthetic.write_cube(outside)
    job = client.submit(outside)
    assert Path(job.model).parent == Path(job.dir)
    assert Path(job.dir).parent == tmp_path / "home" / "jobs"
    assert not any((tmp_path / "home" / "import").iterdir())  # staged copies removed
    os.symlink("/etc/shadow", tmp_path / "shadow.stl")
    with pytest.raises(InputError, match="outside its folder"):
        client.submit(tmp_path / "shadow.stl")
    client.close()


def test_a_job_names_only_profiles_of_the_profile_folders(model: Path, tmp_path: Path) -> None:
    home = tmp_path / "home"
    (home / "profiles").mkdir(parents=True)
    lab = home / "profiles" / "lab.toml"
    lab.write_text((Path("slicer/profiles/ecoflex-0030.toml")).read_text())
    job = tmp_path / "job.toml"
    for ok in ("active", "ecoflex-0030", str(lab)):
        job.write_text(f'[extrusion]\nprofile = "{ok}"\n')
        check_submission(model, job_file=job, home=home)
    stray = tmp_path / "stray.toml"
    stray.write_text(lab.read_text())
    for bad in (str(stray), "/etc/passwd", str(home / "profiles" / ".." / "x.toml")):
        job.write_text(f'[extrusion]\nprofile = "{bad}"\n')
        with pytest.raises(InputError):
            check_submission(model, job_file=job, home=home)
