/* team_node.c: three robots' team layers in three in-process nodes on a loopback group,
 * written from huddle.h alone, no daemon. Each robot program writes its pose every
 * cycle (40 ms) and, when its camera sees the ball, a ball sighting; robots 1 and 2 see
 * the ball, robot 3 is blind. Each reads back from its own node the team ball, the goer
 * and whether it goes (docs/team-layer.md). Then bad inputs are refused with the
 * contract's reason, typed or not.
 *
 *   cc -std=c11 -I ffi/include ffi/examples/team_node.c target/ffi/libhuddle.a \
 *      -lpthread -ldl -lm -o team_node && ./team_node 239.255.7.8 47100
 *
 * Sends only on loopback (interface 127.0.0.1). */
#define _POSIX_C_SOURCE 199309L /* nanosleep */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "huddle.h"

#define ROBOTS 3

/* Where the robots stand (field frame, m, rad) and where the ball lies. */
static const double POSE[ROBOTS][3] = {{0.0, 0.0, 0.0}, {-2.0, 1.0, 0.5}, {-3.0, -2.0, 0.0}};
static const int SEES_BALL[ROBOTS] = {1, 1, 0};
static const double BALL[2] = {1.0, 0.5};

static huddle_node *start(uint8_t robot, const char *group, uint16_t port) {
    huddle_node_config cfg = {0};
    huddle_error err = {0};
    cfg.robot_id = robot;
    cfg.group_address = group;
    cfg.group_port = port;
    cfg.team_size = ROBOTS;
    cfg.refresh_ms = 100;
    huddle_node *node = huddle_node_start(&cfg, &err);
    if (node == NULL) {
        fprintf(stderr, "start robot %d: %s\n", robot, err.message);
        exit(1);
    }
    return node;
}

static void nap_ms(long ms) {
    struct timespec t = {ms / 1000, (ms % 1000) * 1000000L};
    nanosleep(&t, NULL);
}

#define CHECK(call)                                                          \
    do {                                                                     \
        if ((call) < 0) {                                                    \
            fprintf(stderr, "%s failed: %s\n", #call, err.message);          \
            return 1;                                                        \
        }                                                                    \
    } while (0)

/* One cycle of robot i's program: its pose, and the ball in its own frame if it sees it. */
static int feed(huddle_node *node, int i, huddle_error *err) {
    const double *p = POSE[i];
    const double pose_cov[6] = {0.01, 0.0, 0.0, 0.01, 0.0, 0.001};
    if (SEES_BALL[i]) {
        double dx = BALL[0] - p[0], dy = BALL[1] - p[1];
        double c = cos(p[2]), s = sin(p[2]);
        const double ball_cov[3] = {0.01, 0.0, 0.01};
        if (huddle_node_set_robot_ball(node, c * dx + s * dy, -s * dx + c * dy, ball_cov, 0.0, err) < 0)
            return -1;
    }
    /* The pose closes the cycle: the layer ticks on it before this call returns. */
    return huddle_node_set_robot_pose(node, p[0], p[1], p[2], pose_cov, 0.0, err);
}

int main(int argc, char **argv) {
    const char *group = argc > 1 ? argv[1] : "239.255.7.8";
    uint16_t port = (uint16_t)(argc > 2 ? atoi(argv[2]) : 47100);
    huddle_error err = {0};
    huddle_node *node[ROBOTS];
    for (int i = 0; i < ROBOTS; ++i) node[i] = start((uint8_t)(i + 1), group, port);

    /* Up to 10 s of 40 ms cycles, until every robot holds a team ball and all three
     * agree on one goer, the only one going. */
    huddle_team_ball ball[ROBOTS];
    uint8_t goer[ROBOTS];
    int going[ROBOTS], settled = 0, cycles = 0;
    for (; cycles < 250 && !settled; ++cycles) {
        for (int i = 0; i < ROBOTS; ++i) CHECK(feed(node[i], i, &err));
        nap_ms(40);
        int balls = 0, goers = 0, agree = 1;
        for (int i = 0; i < ROBOTS; ++i) {
            int b, g;
            CHECK(b = huddle_node_get_team_ball(node[i], &ball[i], &err));
            CHECK(g = huddle_node_get_team_goer(node[i], &goer[i], &going[i], &err));
            balls += b;
            goers += g && going[i];
            agree &= g && goer[i] != 0 && goer[i] == goer[0];
        }
        settled = balls == ROBOTS && goers == 1 && agree;
    }
    if (!settled) {
        fprintf(stderr, "no shared team ball and single goer after %d cycles\n", cycles);
        return 1;
    }
    /* A few cycles more: the decision holds. */
    int flips = 0;
    for (int k = 0; k < 25; ++k) {
        for (int i = 0; i < ROBOTS; ++i) CHECK(feed(node[i], i, &err));
        nap_ms(40);
        for (int i = 0; i < ROBOTS; ++i) {
            uint8_t g;
            int me;
            CHECK(huddle_node_get_team_goer(node[i], &g, &me, &err));
            flips += g != goer[0] || me != (i + 1 == goer[0]);
        }
    }
    printf("settled after %d cycles; %d changes of mind in 25 more\n", cycles, flips);
    for (int i = 0; i < ROBOTS; ++i) {
        double miss = hypot(ball[i].x - BALL[0], ball[i].y - BALL[1]);
        printf("robot %d%s: team ball (%.2f, %.2f) %.2f m off, confidence %.2f; goer %d, going %d\n",
               i + 1, SEES_BALL[i] ? "" : " (blind)", ball[i].x, ball[i].y, miss, ball[i].confidence,
               goer[i], going[i]);
        if (miss > 0.3) {
            fprintf(stderr, "robot %d's team ball is %.2f m off\n", i + 1, miss);
            return 1;
        }
    }
    size_t mates = 0;
    CHECK(huddle_node_get_team_mates(node[2], NULL, 0, &mates, &err));
    printf("robot 3 knows %zu teammates\n", mates);

    /* Bad inputs: refused with the contract's reason, nothing written. */
    const double cov[6] = {0.01, 0.0, 0.0, 0.01, 0.0, 0.001};
    if (huddle_node_set_robot_pose(node[0], NAN, 0.0, 0.0, cov, 0.0, &err) == 0) return 1;
    printf("refused (%d): %s\n", err.code == HUDDLE_E_VALUE, err.message);
    const double not_pd[5] = {1.0, 0.0, 0.04, 0.05, 0.04};
    if (huddle_node_set_floats(node[0], "local.var.robot.ball", not_pd, 5, &err) == 0) return 1;
    printf("refused (%d): %s\n", err.code == HUDDLE_E_VALUE, err.message);
    if (huddle_node_set(node[0], "local.var.robot.pose", "[1, 2, 3]", &err) == 0) return 1;
    printf("refused (%d): %s\n", err.code == HUDDLE_E_VALUE, err.message);
    const double hours_old = 7200.0;
    const double ball_cov[3] = {0.01, 0.0, 0.01};
    if (huddle_node_set_robot_ball(node[0], 1.0, 0.0, ball_cov, hours_old, &err) == 0) return 1;
    printf("refused (%d): %s\n", err.code == HUDDLE_E_VALUE, err.message);

    for (int i = 0; i < ROBOTS; ++i) huddle_node_stop(node[i]);
    printf("team_node: OK\n");
    return 0;
}
