"""A simulated two-node Ray cluster loses a node in the middle of a batch of fits: the tasks it
was running are retried on the other node and every fit is stored exactly once (issue 23)."""

from __future__ import annotations

import pytest

ray = pytest.importorskip(
    "ray", reason="ray is not installed (pip install plugins/zooctl-ray; make test does)"
)
pytest.importorskip(
    "zooctl_ray", reason="the zooctl-ray plugin is not installed (pip install plugins/zooctl-ray)"
)

from batch_helpers import fit_inputs, fit_records, temporaries, tiny_config  # noqa: E402

from zooctl.executors import get_executor  # noqa: E402
from zooctl.pipelines.batch import Progress, run_batch  # noqa: E402
from zooctl.pipelines.batch_fit import commit_fit, fit_task, plan_fits  # noqa: E402

MB = 1024 * 1024


@pytest.fixture(scope="module")
def cluster():
    from ray.cluster_utils import Cluster

    # The head runs no tasks (0 CPUs): the driver and the progress board live there.
    c = Cluster(
        initialize_head=True,
        head_node_args={
            "num_cpus": 0,
            "object_store_memory": 100 * MB,
            "include_dashboard": False,
            "_system_config": {"health_check_period_ms": 500, "health_check_failure_threshold": 2},
        },
    )
    workers = [c.add_node(num_cpus=1, object_store_memory=100 * MB) for _ in range(2)]
    ray.init(address=c.address, log_to_driver=False)
    c.wait_for_nodes()
    yield c, workers
    ray.shutdown()
    c.shutdown()


def fit_saying_where(task, report):
    """`fit_task` that first names its node, so the test can kill a node while it fits. The
    driver shows each task's latest stage (polled twice a second): the name stays a second."""
    import time

    report("node " + ray.get_runtime_context().get_node_id())
    time.sleep(1.0)
    return fit_task(task, report)


def test_a_node_killed_mid_batch_loses_and_duplicates_nothing(tmp_path, store, cluster):
    import sys

    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])  # workers cannot import tests/
    c, workers = cluster
    doomed = workers[1].node_id
    videos = fit_inputs(tmp_path, store, 6)
    items = plan_fits(videos, store, tiny_config(), template="a0", out_root=tmp_path / "out")
    commits: list[str] = []
    killed: list[str] = []

    def commit(item, value):
        commits.append(item.key)
        return commit_fit(item, value)

    class KillANode(Progress):
        """Once a fit has been stored, kill the node of the next fit that says it runs there."""

        def stage(self, key, stage):
            if commits and not killed and stage == f"node {doomed}":
                killed.append(key)
                c.remove_node(workers[1], allow_graceful=False)

    report = run_batch(get_executor("ray", jobs=4), fit_saying_where, items, commit, progress=KillANode())
    assert killed and workers[1] not in c.worker_nodes
    assert report.count("done") == 6, report.to_json()
    by = {r.key: r for r in report.results}
    assert by[killed[0]].attempts >= 2, report.to_json()  # the fit it was running ran again
    assert sorted(commits) == sorted(it.key for it in items)  # once each: none lost, none twice
    recs = fit_records(store)
    assert sorted(recs) == sorted(commits) and {r["status"] for r in recs.values()} == {"done"}
    assert not temporaries(store)
