"""The swarm middleware's managers, one per concern of the Pet-Bot paper: the sequence manager (a
robot's state), message processing (``exchange``: request/response steps with deadlines), RF communication
(``rf``), network formation (``formation`` runtime + its sans-IO core, ``decisions``), relative location by
infrared (``relative_location``, ``ir_estimator``), and the swarm messages they exchange (``messages``).
"""
