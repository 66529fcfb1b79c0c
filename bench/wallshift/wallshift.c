/* A faketime-like shim for the clock scenarios: moves CLOCK_REALTIME only.

   LD_PRELOAD=wallshift.so WALL_SHIFT_FILE=PATH: every wall-clock reading
   (clock_gettime of CLOCK_REALTIME and its coarse twin, gettimeofday, time) is
   moved by the seconds written in PATH (re-read at most every 50 ms of the
   monotonic clock, so a running process can be stepped). The monotonic clock
   and the kernel's file times are left alone, as on a robot whose clock is
   wrong only where the process reads the time of day. */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/time.h>
#include <time.h>

static int (*real_clock_gettime)(clockid_t, struct timespec *);
static long long shift_ns;
static long long read_at_ns = -1;

static long long monotonic_ns(void) {
    struct timespec ts;
    real_clock_gettime(CLOCK_MONOTONIC, &ts);
    return (long long)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static long long shift(void) {
    if (!real_clock_gettime) real_clock_gettime = dlsym(RTLD_NEXT, "clock_gettime");
    long long now = monotonic_ns();
    if (read_at_ns < 0 || now - read_at_ns > 50000000LL) {
        const char *path = getenv("WALL_SHIFT_FILE");
        FILE *file = path ? fopen(path, "r") : NULL;
        double seconds = 0;
        if (file) {
            if (fscanf(file, "%lf", &seconds) != 1) seconds = 0;
            fclose(file);
        }
        shift_ns = (long long)(seconds * 1e9);
        read_at_ns = now;
    }
    return shift_ns;
}

int clock_gettime(clockid_t id, struct timespec *ts) {
    long long moved = shift();
    int result = real_clock_gettime(id, ts);
    if (result == 0 && (id == CLOCK_REALTIME || id == CLOCK_REALTIME_COARSE)) {
        long long ns = (long long)ts->tv_sec * 1000000000LL + ts->tv_nsec + moved;
        ts->tv_sec = ns / 1000000000LL;
        ts->tv_nsec = ns % 1000000000LL;
    }
    return result;
}

int gettimeofday(struct timeval *tv, void *tz) {
    struct timespec ts;
    (void)tz;
    clock_gettime(CLOCK_REALTIME, &ts);
    tv->tv_sec = ts.tv_sec;
    tv->tv_usec = ts.tv_nsec / 1000;
    return 0;
}

time_t time(time_t *out) {
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    if (out) *out = ts.tv_sec;
    return ts.tv_sec;
}
