"""The colours every view of a run shares (report, replay, live map), so that a reason or a label
looks the same in each."""

DROP_COLORS = {"out_of_range": "#9467bd", "loss": "#d62728", "queue_full": "#ff7f0e", "receiver_dead": "#7f7f7f",
               "no_such_receiver": "#8c564b", "run_ended": "#bcbd22", "late": "#17becf"}
LABEL_COLORS = {"red": "#d62728", "green": "#2ca02c", "blue": "#1f77b4"}  # SAR's robot and victim colours
