"""What a run leaves behind: the names and safe reading of a run folder's files (``rundir.py``),
``summary.json``'s model (``summary.py``: ``RunSummary``, built by the recorder, read typed by every
reader) and result tables written as a run goes in whole-row chunks (``rowfile.py``). Above the
wire contract, below every process that writes results and every view that reads them."""
