/* A hostile FMU (see model.h): healthy until fault_time, then its fault. */
#define _POSIX_C_SOURCE 200809L
#include "model.h"

#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>
#include <unistd.h>

#define QA_MAX 9.05e-4
#define QB_MAX 11.1e-4
#define GAIN 2000.0      /* plant: steady level per flow [m / (m3/s)] */
#define TAU 500.0        /* plant: time constant [s] */
#define KI 4e-5          /* controller: integral gain per sample [m3/s / m] */
#define FLOOD_BYTES (1 << 20) /* written to standard output by a flooding step */
#define FLOOD_WARNINGS 200    /* warnings logged by a flooding step */

static const char *const NAMES[N_VARIABLES] = {
#ifdef HOSTILE_CONTROLLER
    "time", "h1", "h2", "ref.h1", "ref.h2", "qa", "qb", "status", "fallback", "iterations",
    "fault", "fault_time"
#else
    "time", "h1", "h2", "qa", "qb", "fault", "fault_time"
#endif
};

void model_set_defaults(ModelData *m) {
    memset(m, 0, sizeof *m);
    m->h[0] = m->h[1] = 0.65;
    m->ref[0] = m->ref[1] = 0.65;
    m->q[0] = 0.5 * QA_MAX;
    m->q[1] = 0.5 * QB_MAX;
    m->fault_time = 1e300;
}

/* The fault, once its time has come (a flood returns; everything else never does). */
static void misbehave(ModelData *m) {
    switch ((int)m->fault) {
    case FAULT_HANG: {
        volatile unsigned long spin = 0;
        for (;;) spin++;
    }
    case FAULT_SEGFAULT: {
        volatile int *volatile p = NULL;
        *p = 1;
        break;
    }
    case FAULT_ABORT:
        fprintf(stderr, "hostile: giving up at t = %g s\n", m->time);
        abort();
    case FAULT_EXIT:
        exit(0);
    case FAULT_FLOOD: {
        static char line[1024];
        memset(line, 'x', sizeof line - 1);
        line[sizeof line - 2] = '\n';
        for (int i = 0; i < FLOOD_BYTES / (int)(sizeof line - 1); i++)
            fputs(line, stdout);
        fflush(stdout);
        m->flooding = FLOOD_WARNINGS;
        break;
    }
    case FAULT_SIGNAL:
        signal(SIGTERM, SIG_DFL);
        kill(0, SIGTERM); /* its whole process group */
        break;
    default:
        break;
    }
}

void model_initialize(ModelData *m) {
    if (m->fault_time <= m->time) misbehave(m);
}

const char *model_variable_name(unsigned vr) { return vr < N_VARIABLES ? NAMES[vr] : NULL; }

double model_get(const ModelData *m, unsigned vr) {
    switch (vr) {
    case VR_TIME: return m->time;
    case VR_H1: return m->h[0];
    case VR_H2: return m->h[1];
    case VR_QA: return m->q[0];
    case VR_QB: return m->q[1];
    case VR_FAULT: return m->fault;
    case VR_FAULT_TIME: return m->fault_time;
#ifdef HOSTILE_CONTROLLER
    case VR_REF1: return m->ref[0];
    case VR_REF2: return m->ref[1];
    default: return 0.0; /* status, fallback, iterations */
#else
    default: return 0.0;
#endif
    }
}

const char *model_set(ModelData *m, unsigned vr, double value, bool initialized) {
    (void)initialized;
    switch (vr) {
#ifdef HOSTILE_CONTROLLER
    case VR_H1: m->h[0] = value; return NULL;
    case VR_H2: m->h[1] = value; return NULL;
    case VR_REF1: m->ref[0] = value; return NULL;
    case VR_REF2: m->ref[1] = value; return NULL;
#else
    case VR_QA: m->q[0] = value; return NULL;
    case VR_QB: m->q[1] = value; return NULL;
#endif
    case VR_FAULT: m->fault = value; return NULL;
    case VR_FAULT_TIME: m->fault_time = value; return NULL;
    default: return "is not an input or parameter";
    }
}

const char *model_state_name(size_t i) { (void)i; return ""; }
void model_get_states(const ModelData *m, double *x) { (void)m, (void)x; }
void model_set_states(ModelData *m, const double *x) { (void)m, (void)x; }
void model_get_derivatives(const ModelData *m, double *dx) { (void)m, (void)dx; }

#ifdef HOSTILE_CONTROLLER
static double clamp(double x, double lo, double hi) { return x < lo ? lo : x > hi ? hi : x; }
#endif

const char *model_do_step(ModelData *m, double step, char *msg, size_t n) {
    (void)msg, (void)n;
    if (m->time >= m->fault_time) misbehave(m);
#ifdef HOSTILE_CONTROLLER
    (void)step;
    m->q[0] = clamp(m->q[0] + KI * (m->ref[1] - m->h[1]), 0.0, QA_MAX);
    m->q[1] = clamp(m->q[1] + KI * (m->ref[0] - m->h[0]), 0.0, QB_MAX);
#else
    const double decay = exp(-step / TAU);
    m->h[0] = GAIN * m->q[1] + (m->h[0] - GAIN * m->q[1]) * decay;
    m->h[1] = GAIN * m->q[0] + (m->h[1] - GAIN * m->q[0]) * decay;
#endif
    m->time += step;
    return NULL;
}

const char *model_warning(ModelData *m, char *msg, size_t n) {
    if (m->flooding <= 0) return NULL;
    m->flooding--;
    snprintf(msg, n, "hostile: flooding the log at t = %g s (%d more)", m->time, m->flooding);
    return msg;
}
