/* typed_node.c: two robots on a loopback group, written from huddle.h alone: typed set
 * and get (no text in between), a long value read whole through a length query,
 * value-changed events, the key list and the stats (the struct, and a counter by name).
 *
 *   cc -std=c11 -I ffi/include ffi/examples/typed_node.c target/ffi/libhuddle.a \
 *      -lpthread -ldl -lm -o typed_node && ./typed_node 239.255.7.7 47000
 *
 * Sends only on loopback (interface 127.0.0.1). */
#define _POSIX_C_SOURCE 199309L /* nanosleep */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "huddle.h"

static huddle_node *start(uint8_t robot, const char *group, uint16_t port) {
    huddle_node_config cfg = {0};
    huddle_error err = {0};
    cfg.robot_id = robot;
    cfg.group_address = group;
    cfg.group_port = port;
    cfg.refresh_ms = 100; /* departed after 300 ms of silence: slow machines too */
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

int main(int argc, char **argv) {
    const char *group = argc > 1 ? argv[1] : "239.255.7.7";
    uint16_t port = (uint16_t)(argc > 2 ? atoi(argv[2]) : 47000);
    huddle_error err = {0};
    huddle_node *one = start(1, group, port);
    huddle_node *two = start(2, group, port);
    CHECK(huddle_node_watch(two, "+.var.ball.#", &err));

    double ball[3] = {0.33, -2.25, 0.1};
    CHECK(huddle_node_set_floats(one, "*.var.ball.pos", ball, 3, &err));
    CHECK(huddle_node_set_int(one, "*.var.mode", 3, &err));
    CHECK(huddle_node_set_string(one, "*.var.role", "striker", &err));

    /* The changed ball arrives as an event, with the value. */
    huddle_event ev;
    int got = 0;
    for (int i = 0; i < 100 && !got; ++i) {
        CHECK(huddle_node_next_event(two, 50, &ev, &err));
        got = ev.kind == HUDDLE_EVENT_VALUE_CHANGED;
    }
    if (!got) {
        fprintf(stderr, "no value-changed event\n");
        return 1;
    }
    printf("changed: %s = %s (robot %d)\n", ev.name, ev.value, ev.robot);

    double pos[3];
    size_t n = 0;
    CHECK(huddle_node_get_floats(two, "1.var.ball.pos", pos, 3, &n, &err));
    int64_t mode = 0;
    for (int i = 0; i < 100 && huddle_node_get_int(two, "1.var.mode", &mode, &err) == 0; ++i) nap_ms(10);
    printf("robot 2 reads ball (%g, %g, %g), mode %lld\n", pos[0], pos[1], pos[2], (long long)mode);

    /* A string of unknown length: ask for the length, then read all of it. */
    for (int i = 0; i < 100 && huddle_node_get_string(two, "1.var.role", NULL, 0, &n, &err) == 0; ++i) nap_ms(10);
    char *role = malloc(n + 1);
    CHECK(huddle_node_get_string(two, "1.var.role", role, n + 1, &n, &err));
    printf("role: %s (%zu bytes)\n", role, n);
    free(role);

    /* A type mismatch is an error, not a silent conversion. */
    if (huddle_node_get_int(two, "1.var.role", &mode, &err) != -1 || err.code != HUDDLE_E_TYPE) {
        fprintf(stderr, "a string read as an int was not refused\n");
        return 1;
    }
    printf("refused: %s\n", err.message);

    /* 2000 floats: their literal is far beyond huddle_binding's 1023 bytes. */
    double *many = malloc(2000 * sizeof *many);
    for (int i = 0; i < 2000; ++i) many[i] = i * 0.25;
    CHECK(huddle_node_set_floats(one, "local.var.map", many, 2000, &err));
    CHECK(huddle_node_get_literal(one, "local.var.map", NULL, 0, &n, &err));
    char *literal = malloc(n + 1);
    CHECK(huddle_node_get_literal(one, "local.var.map", literal, n + 1, &n, &err));
    printf("literal of %zu bytes, ends %s\n", n, literal + n - 8);
    free(literal);
    free(many);

    char keys[256];
    int count = huddle_node_keys(two, "1.var.#", keys, sizeof keys, &n, &err);
    CHECK(count);
    printf("%d keys of robot 1:\n%s", count, keys);
    huddle_stats stats;
    CHECK(huddle_node_stats(two, &stats, &err));
    printf("robot 2: %d peer(s) present, %llu frames in\n", stats.peers_present,
           (unsigned long long)stats.frames_in);
    /* Counters added after huddle_stats was fixed are read by name: 1 found, 0 when
     * this library has no such counter (an older one), -1 on error. */
    uint64_t unknown_values = 0, dropped = 0;
    CHECK(huddle_node_stats_counter(two, "talk_unknown_value", &unknown_values, &err));
    CHECK(huddle_node_stats_counter(two, "drops.total", &dropped, &err));
    int found = huddle_node_stats_counter(two, "no_such_counter", &dropped, &err);
    printf("robot 2: talk_unknown_value %llu, drops %llu, no_such_counter found %d\n",
           (unsigned long long)unknown_values, (unsigned long long)dropped, found);
    huddle_node_stop(one);
    huddle_node_stop(two);
    printf("typed_node: OK\n");
    return 0;
}
