"""The IEEE 802.15.4 air: frames (``mac``), the medium (CSMA-CA, airtime, collisions, ACKs, loss),
propagation, chaos (faults changed at run time) and the pcap of what went on the air. Pure: time is passed in.
"""
