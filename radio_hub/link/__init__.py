"""How a node and the hub talk: the messages (``wire``), zenoh key expressions (``keys``), the radio
port a node uses (``port``: ``RadioClient`` over a ``HubLink``, no zenoh) and the zenoh link for processes.
Nodes reach these through ``radio_hub.interface``.
"""
