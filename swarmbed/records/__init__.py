"""What a run leaves behind: the run folder as it is written and read (``run_folder.py``: its file
names, and ``RunDir``, every bounded read of a folder someone else may have made),
``summary.json``'s model (``summary.py``: ``RunSummary``, built by the recorder, read typed by every
reader) and result tables written as a run goes in whole-row chunks (``rowfile.py``). Below every
process that writes results and every view that reads them."""
