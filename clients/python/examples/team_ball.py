"""Three robots feed their daemons' team layers; each daemon then knows the team ball.

    python3 team_ball.py 2001 2002 2003    # the relay ports of robots 1, 2 and 3

Robot 1 sees the ball 1.5 m ahead; robots 2 and 3 do not see it at all. Every robot
writes its pose at 30 Hz (docs/team-layer.md: REP-103 field frame, metres, radians);
robot 1 also writes each ball sighting (robot frame).
"""
import sys
import time

from huddle_client import Relay

POSES = [(-1.0, 0.0, 0.0), (-3.0, 1.5, 0.0), (-3.0, -1.5, 0.0)]  # x, y, theta
POSE_COV = [[0.01, 0, 0], [0, 0.01, 0], [0, 0, 0.003]]
relays = [Relay("127.0.0.1", int(port)) for port in sys.argv[1:4]]
for _ in range(60):  # two seconds at 30 Hz
    for robot, (x, y, theta) in zip(relays, POSES):
        robot.set_pose(x, y, theta, POSE_COV)
    relays[0].ball_seen(1.5, 0.0, [[0.01, 0], [0, 0.01]])
    time.sleep(1 / 30)
for robot in relays:
    ball = robot.team_ball()
    assert ball is not None, f"robot {robot.robot} has no team ball"
    print(f"robot {robot.robot}: team ball at ({ball.x:.2f}, {ball.y:.2f}),"
          f" confidence {ball.confidence:.2f}, goer {robot.goer()}")
    robot.close()
