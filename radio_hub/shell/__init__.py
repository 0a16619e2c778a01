"""The processes around the environment: the hub (``hub``: zenoh shell on the wall clock) and
lockstep (``lockstep``: the hub owning model time, the nodes' link).
"""
