"""What moves a robot: the driver (``driving``: the modes of Table 3), the pet (master) and
slave controllers, formation shapes, the surround formation (law, pilot, driver, sensing) and the
kinematics they share (``motion``).
"""
