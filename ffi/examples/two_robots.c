/* two_robots.c: two huddle nodes in one process on a loopback multicast group.
 *
 * Robot 1 sets *.var.ball.dist; robot 2 reads it as 1.var.ball.dist with its age.
 * Robot 1 then posts 100 talk messages; robot 2 checks that all arrive, in order.
 *
 *   cc -I ffi/include ffi/examples/two_robots.c target/debug/libhuddle.a \
 *      -lpthread -ldl -lm -o two_robots && ./two_robots 239.255.7.7 47000
 *
 * Written from huddle.h alone. Sends only on loopback (interface 127.0.0.1).
 */
#define _POSIX_C_SOURCE 200809L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "huddle.h"

static double now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
}

static huddle_node *start(uint8_t id, const char *group, uint16_t port) {
    huddle_node_config cfg;
    memset(&cfg, 0, sizeof cfg); /* zero: every other field takes its default */
    cfg.robot_id = id;
    cfg.team_id = 7;
    cfg.group_address = group;
    cfg.group_port = port;
    cfg.interface_address = "127.0.0.1";
    huddle_error err;
    huddle_node *node = huddle_node_start(&cfg, &err);
    if (node == NULL) {
        fprintf(stderr, "robot %d: cannot start: %s (code %d)\n", id, err.message, err.code);
        exit(1);
    }
    return node;
}

int main(int argc, char **argv) {
    const char *group = argc > 1 ? argv[1] : "239.255.7.7";
    uint16_t port = (uint16_t)(argc > 2 ? atoi(argv[2]) : 47000);
    huddle_error err;
    printf("huddle %s, group %s:%u on loopback\n", huddle_version(), group, port);

    double t0 = now_ms();
    huddle_node *robot1 = start(1, group, port);
    huddle_node *robot2 = start(2, group, port);

    /* A value: set on robot 1, read on robot 2 with its age. */
    if (huddle_node_set(robot1, "*.var.ball.dist", "1.5", &err) != 0) {
        fprintf(stderr, "set: %s\n", err.message);
        return 1;
    }
    huddle_binding b;
    int found = 0;
    while (!found && now_ms() - t0 < 1000.0) {
        found = huddle_node_get(robot2, "1.var.ball.dist", &b, &err);
        if (found < 0) {
            fprintf(stderr, "get: %s\n", err.message);
            return 1;
        }
    }
    if (!found) {
        fprintf(stderr, "robot 2 never saw 1.var.ball.dist\n");
        return 1;
    }
    printf("robot 2 read %s = %s (%s, owner %u, age %llu ms), %.1f ms after start\n", b.key,
           b.value, b.type, b.owner, (unsigned long long)b.age_ms, now_ms() - t0);

    /* Bad arguments are errors, never crashes. */
    if (huddle_node_set(robot1, "2.var.x", "1", &err) != -1 || err.code != HUDDLE_E_KEY) {
        fprintf(stderr, "another robot's key was accepted\n");
        return 1;
    }
    printf("refused: %s\n", err.message);
    if (huddle_node_set(robot1, "*.var.x", "not a literal", &err) != -1 ||
        err.code != HUDDLE_E_LITERAL) {
        fprintf(stderr, "a bad literal was accepted\n");
        return 1;
    }
    printf("refused: %s\n", err.message);

    /* 100 talk messages, in order, exactly once. */
    char literal[32];
    for (int i = 1; i <= 100; i++) {
        snprintf(literal, sizeof literal, "%d", i * 10);
        uint64_t seq = 0;
        if (huddle_node_post(robot1, "*.talk.plan", literal, &seq, &err) != 0 || seq != (uint64_t)i) {
            fprintf(stderr, "post %d: %s\n", i, err.message);
            return 1;
        }
    }
    int delivered = 0;
    huddle_event ev;
    double deadline = now_ms() + 5000.0;
    while (delivered < 100 && now_ms() < deadline) {
        int got = huddle_node_next_event(robot2, 100, &ev, &err);
        if (got < 0) {
            fprintf(stderr, "next_event: %s\n", err.message);
            return 1;
        }
        if (got == 0) continue;
        if (ev.kind == HUDDLE_EVENT_TALK_DELIVERED) {
            delivered++;
            snprintf(literal, sizeof literal, "%d", delivered * 10);
            if (ev.robot != 1 || strcmp(ev.name, "plan") != 0 || ev.seq != (uint64_t)delivered ||
                strcmp(ev.value, literal) != 0) {
                fprintf(stderr, "message %d out of order: robot %u queue %s seq %llu value %s\n",
                        delivered, ev.robot, ev.name, (unsigned long long)ev.seq, ev.value);
                return 1;
            }
        } else if (ev.kind == HUDDLE_EVENT_TALK_GIVEN_UP || ev.kind == HUDDLE_EVENT_LAGGED) {
            fprintf(stderr, "talk lost (event %d)\n", ev.kind);
            return 1;
        } else if (ev.kind == HUDDLE_EVENT_PEER_JOINED) {
            printf("robot 2: robot %u joined\n", ev.robot);
        }
    }
    printf("robot 2 got %d talk messages from robot 1, in order\n", delivered);

    huddle_node_stop(robot1);
    huddle_node_stop(robot2);
    /* After stop the pointer is dead: an error, not a crash. */
    if (huddle_node_set(robot1, "*.var.x", "1", &err) != -1 || err.code != HUDDLE_E_STOPPED) {
        fprintf(stderr, "use after stop was not refused\n");
        return 1;
    }
    printf("after stop: %s\n", err.message);
    if (delivered != 100) return 1;
    printf("two_robots: OK\n");
    return 0;
}
