"""The parallel-jaw hand (Franka Hand dimensions) and the grasp-frame convention.

Grasp frame G: origin at the grasp point on the object surface, +z the approach
direction (pointing into the object), +y the finger closing direction. The hand
frame H sits at the arm's flange with the same axes: +z out of the palm, fingers
sliding along +-y. The hand is placed so that its TCP lies `GRASP_DEPTH` beyond
the grasp point along the approach axis; `X_GH` is that one constant, used by
data collection, selection and execution alike. The same hand is mounted on every
arm, so the stability CNN is robot-independent and only the RP is per robot.
"""

from __future__ import annotations

from pydrake.math import RigidTransform

PALM_DEPTH = 0.0584  # flange to finger base [m]
FINGER_LENGTH = 0.055  # finger base to fingertip [m]
TCP_DEPTH = 0.1034  # flange to TCP, Franka's published value [m]
MAX_HALF_OPENING = 0.04  # each finger travels 0-40 mm: 0-80 mm stroke
PALM_SIZE = (0.063, 0.204)  # palm box along x_H, y_H [m] (its depth along z_H is PALM_DEPTH)
FINGER_SIZE = (0.02, 0.012)  # finger pad box along x_H, y_H [m] (its length along z_H is FINGER_LENGTH)
FINGER_EFFORT_N = 40.0  # finger actuator force limit [N]; the coupler splits it: 20 N per finger
TCP_DEPTH_TO_TIP = PALM_DEPTH + FINGER_LENGTH - TCP_DEPTH  # fingertips beyond the TCP
GRASP_DEPTH = 0.01  # TCP beyond the grasp point: fingertips 20 mm past the surface

HAND_OPEN = MAX_HALF_OPENING  # commanded finger position, open [m]
HAND_CLOSED = 0.0  # commanded finger position, closed (the force limit decides the grip) [m]

X_GT = RigidTransform([0.0, 0.0, GRASP_DEPTH])  # TCP in the grasp frame
X_HT = RigidTransform([0.0, 0.0, TCP_DEPTH])  # TCP in the hand frame
X_GH = X_GT @ X_HT.inverse()  # hand frame in the grasp frame
