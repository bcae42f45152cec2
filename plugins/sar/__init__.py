"""The coordination strategies of the CBBA-ETC evaluation for the search-and-rescue scenario:
``tree``, ``comm``, ``cbba``, ``cbba-tree``, ``cbba-etc`` and ``c-cbba`` (see the registry)."""
