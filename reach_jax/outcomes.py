"""How a trial or a test movement ends: the codes that training, the per-trial log and the evaluation share."""

SUCCESS, OUT, FAIL = 0, 1, 2  # at the goal; a joint left its range; neither in time (a trial's cap, a test's 4 s)
NAMES = ("success", "out", "fail")  # indexed by the code
