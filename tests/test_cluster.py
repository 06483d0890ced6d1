"""``smc replay --cluster``: what a user gets when the cluster is not there.

The campaign on a real Dask cluster (a ``LocalCluster`` on 127.0.0.1, the same results as
local processes, no process left behind) is in ``test_campaign.py``.
"""

from __future__ import annotations

import os
import socket

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

from conftest import smc  # noqa: E402

from smccli.errors import SmcError  # noqa: E402
from smccli.execute import campaign as cp  # noqa: E402


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_a_scheduler_that_does_not_answer_is_named(sample_trees, monkeypatch) -> None:
    monkeypatch.setattr(cp, "CLUSTER_TIMEOUT", 2.0)  # the user's wait is 10 s
    address = f"tcp://127.0.0.1:{_free_port()}"
    with pytest.raises(SmcError) as err:
        cp.run_campaign(sample_trees["bench_pick"], trials=2, cluster=address)
    msg = str(err.value)
    assert msg.startswith(f"--cluster {address}: no Dask scheduler answered") and "\n" not in msg


def test_cluster_options_without_a_campaign_are_refused(sample_trees) -> None:
    r = smc("replay", sample_trees["bench_pick"], "--cluster", "tcp://127.0.0.1:8786")
    assert r.returncode == 2 and "give --trials N" in r.stderr and "Traceback" not in r.stderr
