"""Three robots feed their daemons' team layers; each daemon then knows the team ball.

    python3 team_ball.py 2001 2002 3003    # the relay ports of robots 1, 2 and 3

Robot 1 sees the ball 1.5 m ahead; robots 2 and 3 do not see it at all. Every robot
writes its pose at 30 Hz (docs/team-layer.md: REP-103 field frame, covariance as an
upper triangle); robot 1 also writes each ball sighting (robot frame).
"""
import sys
import time

from huddle_client import Relay

POSES = [(-1.0, 0.0, 0.0), (-3.0, 1.5, 0.0), (-3.0, -1.5, 0.0)]  # x, y, theta
relays = [Relay("127.0.0.1", int(port)) for port in sys.argv[1:4]]
for _ in range(60):  # two seconds at 30 Hz
    for robot, (x, y, th) in zip(relays, POSES):
        robot.set("local.var.robot.pose", [x, y, th, 0.01, 0, 0, 0.01, 0, 0.003])
    relays[0].set("local.var.robot.ball", [1.5, 0.0, 0.01, 0.0, 0.01])
    time.sleep(1 / 30)
for robot in relays:
    ball = robot.get("local.var.team.ball")  # [x, y, vx, vy, var_x, cov_xy, var_y, confidence, age_s]
    goer = robot.get("local.var.team.goer")
    assert ball is not None, f"robot {robot.robot} has no team ball"
    x, y = ball.value[0], ball.value[1]
    print(f"robot {robot.robot}: team ball at ({x:.2f}, {y:.2f}), goer {goer.value}")
    robot.close()
