"""The swarm middleware's managers, one per concern of the Pet-Bot paper: the sequence manager (a
robot's state; ``event_log``, its record), message processing (``exchange``: a request/response step with
deadlines, sans-IO; ``message_processing`` runs steps on the loop), RF communication (``rf``), network
formation (``formation`` runtime + its sans-IO core, ``decisions``), relative location by infrared
(``relative_location`` runtime + ``token_schedule``, ``ir_estimator``), the swarm messages they exchange
(``messages``) and the vocabulary the sans-IO cores share (``actions``).
"""
