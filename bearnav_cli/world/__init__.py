"""The simulated world that ``bearnav simulate`` drives robots in (it is not what a robot runs).

What a robot runs is :mod:`bearnav_cli.runtime`; this package stands in for everything around it:
the camera that measures bearings, the motion of the base, collisions and clearance, and (for
``--camera render``) the images a real camera would take and a real AprilTag detector.
"""
