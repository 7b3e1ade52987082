"""Threads set once (semmatch.runtime.threads): which number, where it is set, and that a block
restores it."""

from __future__ import annotations

import pytest

from semmatch.runtime import threads


@pytest.fixture
def clean_env(monkeypatch):
    """No thread variable set; whatever the test sets is undone afterwards (torch's threads too)."""
    import torch
    from threadpoolctl import threadpool_info, threadpool_limits

    for name in (threads.THREADS_ENV, *threads.ENV_VARS):
        monkeypatch.delenv(name, raising=False)
    before = torch.get_num_threads()
    pools = {pool["user_api"]: pool["num_threads"] for pool in threadpool_info()}
    monkeypatch.setattr(threads, "_CONFIGURED", {})
    yield monkeypatch
    torch.set_num_threads(before)
    threadpool_limits(limits=pools)


def test_the_number_comes_from_semmatch_threads_then_omp_then_one(clean_env):
    assert threads.threads_for("cli") == 1 and threads.threads_for("worker") == 1
    clean_env.setenv("OMP_NUM_THREADS", "3")
    assert threads.threads_for() == 3
    clean_env.setenv(threads.THREADS_ENV, "2")
    assert threads.threads_for() == 2
    clean_env.setenv(threads.THREADS_ENV, "0")  # the libraries' defaults
    assert threads.threads_for() == 0
    for name, bad in ((threads.THREADS_ENV, "two"), (threads.THREADS_ENV, "-1")):
        clean_env.setenv(name, bad)
        with pytest.raises(ValueError, match=name):
            threads.threads_for()
    clean_env.delenv(threads.THREADS_ENV)
    clean_env.setenv("OMP_NUM_THREADS", "0")
    with pytest.raises(ValueError, match="OMP_NUM_THREADS"):
        threads.threads_for()
    with pytest.raises(ValueError, match="unknown kind"):
        threads.threads_for("gpu")


def test_configure_sets_the_variables_and_the_loaded_libraries(clean_env):
    import torch
    from threadpoolctl import threadpool_info

    torch.set_num_threads(2)
    assert threads.configure("cli") == 1
    assert all(__import__("os").environ[name] == "1" for name in threads.ENV_VARS)
    assert torch.get_num_threads() == 1
    assert all(pool["num_threads"] == 1 for pool in threadpool_info())
    assert threads.current()["torch"] == 1
    clean_env.setenv(threads.THREADS_ENV, "0")
    torch.set_num_threads(2)
    assert threads.configure("cli") == 0 and torch.get_num_threads() == 2  # left alone


def test_limit_threads_restores_the_previous_limits(clean_env):
    import torch
    from threadpoolctl import threadpool_info

    torch.set_num_threads(2)
    before = [pool["num_threads"] for pool in threadpool_info()]
    with threads.limit_threads() as n:
        assert n == 1 and torch.get_num_threads() == 1
        assert all(pool["num_threads"] == 1 for pool in threadpool_info())
    assert torch.get_num_threads() == 2
    assert [pool["num_threads"] for pool in threadpool_info()] == before
    with pytest.raises(ValueError, match=">= 0"):
        with threads.limit_threads(-1):
            pass


def test_the_cli_sets_threads_at_its_entry_point(clean_env, capsys):
    import json

    from semmatch.cli import main

    clean_env.setenv(threads.THREADS_ENV, "many")
    assert main(["bench", "fusion", "--frames", "1"]) == 2
    assert "SEMMATCH_THREADS='many' is not a whole number" in capsys.readouterr().err
    clean_env.delenv(threads.THREADS_ENV)
    assert main(["bench", "fusion", "--json", "--frames", "2", "--width", "64", "--height", "48"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["threads"]["torch"] == 1 and res["threads"]["OMP_NUM_THREADS"] == "1"
    assert set(res["threads"]["runtimes"].values()) == {1}


def test_thread_rows_rerun_the_same_benchmark_options():
    from semmatch.cli import build_parser
    from semmatch.cli.bench import _argv_of

    parser = build_parser()
    argv = ["bench", "fusion", "--frames", "7", "--probabilities", "--voxel-size", "0.05", "--width", "320",
            "--scene-kind", "office", "--thread-rows"]
    args = parser.parse_args(argv)
    again = parser.parse_args(["bench", "fusion", *_argv_of(args)])
    words = _argv_of(args)  # old spellings given back canonically
    assert words[words.index("--image-size") + 1] == "320x480" and "--width" not in words
    for key in ("frames", "probabilities", "voxel_size", "image_size", "scene_kind"):
        assert getattr(again, key) == getattr(args, key)
    assert again.thread_rows is False  # the rows themselves run without it
    seg = parser.parse_args(["bench", "segment", "--no-flip", "--model", "a.pt", "b.pt", "--threads", "2"])
    assert _argv_of(seg) == ["--model", "a.pt", "b.pt", "--no-flip"]


def test_opencv_pool_is_limited_and_restored():
    import cv2

    from semmatch.runtime.threads import limit_threads

    before = cv2.getNumThreads()
    cv2.setNumThreads(2)
    try:
        with limit_threads(1):
            assert cv2.getNumThreads() == 1
        assert cv2.getNumThreads() == 2
    finally:
        cv2.setNumThreads(before)
