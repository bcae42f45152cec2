"""The shipped scenarios: SPACE's multi-task single-robot world (:mod:`.mtsr`) and the CBBA-ETC
search-and-rescue world (:mod:`.sar`), each a :class:`~swarmbed.extension.Scenario` registered by
name in :mod:`swarmbed.plugins.registry`. The coordinator drives their worlds; agents build the
scenario for its sensing, its nodes and its typed observation."""
