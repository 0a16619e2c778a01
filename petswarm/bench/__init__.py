"""The benchmarks behind ``petswarm bench``: the hub's throughput and latency (``hub``, ``nodes``),
network formation (``organize``), IR relative location (``ir``, ``ir_token``), reaction to the user
(``reaction``), scale (``scale``) and the surround formation (``surround``, ``surround_sim``). Each writes its
figures and results the same way (``output``).
"""
