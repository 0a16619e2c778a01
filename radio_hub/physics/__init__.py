"""The ground truth and the physics derived from it: the world (poses, kinematics, obstacles,
ultrasonic ranges), IR light (``light``: emission and the 12-receiver readings; ``ir_air``: sweeps),
the LF field of the robots' antennas (``lf``) and BLE links (``ble``). Pure: time is passed in. Robots know
only the datasheet of these parts (``radio_hub.datasheet``).
"""
