"""Learning on the emulated radio: swarmbed experiments as PettingZoo environments (docs/learning.md)."""

from swarmbed.envs.parallel import EnvError, SwarmbedParallelEnv, parallel_env

__all__ = ["EnvError", "SwarmbedParallelEnv", "parallel_env"]
