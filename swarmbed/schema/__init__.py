"""The experiment's declared shape: every section and key of an experiment file as typed models
(``experiment.py``: ``Experiment`` and its sections, ``MAX_TASKS`` and the other bounds; the walls'
section and the one geometric test every part asks of them in ``obstacles.py``; the radio's
sections in ``radio_sections.py``). Above the wire contract, below everything that reads an
experiment."""
