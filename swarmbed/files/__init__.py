"""Files someone else may have made or received: writes that never follow a link (whole files
renamed into place, growing files created fresh) and reads that are bounded and refuse devices and
FIFOs (``safefiles.py``), and YAML read as hostile input into plain values with one-line errors
(``yamlfile.py``). The lowest layer: it imports nothing of swarmbed, and every other layer uses it."""
