"""What reaches Slurm from outside is checked with one rule and refused in one line (issue 82,
item 15): node names that cannot name a host, a job id that is not one, control characters that
would become lines of a batch script."""

import pytest

from swarmbed.launch.slurm_allocation import SlurmError, _usable, read_allocation


@pytest.mark.parametrize("node", ["..", "-h", "a/b", "x" * 80, "n 1", ""])
def test_a_node_name_that_cannot_name_a_host_is_unusable(node):
    assert not _usable(node)


@pytest.mark.parametrize("node", ["n1", "node-07", "gpu_3.cluster"])
def test_a_node_name_of_a_host_is_usable(node):
    assert _usable(node)


@pytest.mark.parametrize("job", ["12/../..", "../../tmp/x", "1\n2", "abc"])
def test_a_job_id_that_is_not_one_is_refused_before_it_names_a_folder(job):
    with pytest.raises(SlurmError, match="not a Slurm job id"):
        read_allocation({"SLURM_JOB_ID": job, "SLURM_JOB_NODELIST": "n1"})


@pytest.mark.parametrize("flag", ["partition", "cluster"])
def test_a_control_character_never_reaches_a_batch_script(tmp_path, flag):
    pytest.importorskip("submitit")
    from swarmbed.campaigns import executors

    with pytest.raises(executors.ExecutorError, match="control character"):
        executors.get("slurm", folder=tmp_path / ".submitit", **{flag: "lab\n#SBATCH --wrap=evil"})
