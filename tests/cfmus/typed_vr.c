/* An FMI 2.0 Co-Simulation FMU whose variables of three base types share value references,
 * as the standard allows (a value reference is unique per base type only): built by the
 * test suite with gcc to prove that twinbench keeps them apart everywhere.
 *
 *   value reference 0: Real output y, Integer output n, Boolean output b
 *   value reference 1: Real input u, Integer input k, Boolean input on
 *   value reference 2: Real parameter gain (2.0), Integer parameter count (3),
 *                      Boolean parameter flag (false)
 *
 * After each step (and at initialisation):
 *   y = gain * u + t,  n = count * k + steps,  b = on XOR flag XOR (t >= 0.5)
 * with t the time reached and steps the number of steps done.
 *
 * Only the C types are used (no FMI headers): fmi2Component = void*, fmi2Status = int,
 * fmi2Boolean = int. */
#include <stdlib.h>
#include <string.h>

#include "fmi2_common.h"

typedef struct {
    double y, u, gain, t;
    int n, k, count, steps;
    int b, on, flag;
} Model;

static void reset(Model *m) {
    memset(m, 0, sizeof(Model));
    m->gain = 2.0;
    m->count = 3;
}

static void outputs(Model *m) {
    m->y = m->gain * m->u + m->t;
    m->n = m->count * m->k + m->steps;
    m->b = (m->on != 0) ^ (m->flag != 0) ^ (m->t >= 0.5);
}

FMI2_MODEL_INSTANCE(Model, reset)

int fmi2SetupExperiment(void *c, int tol_defined, double tol, double start, int stop_defined,
                        double stop) {
    (void)tol_defined; (void)tol; (void)stop_defined; (void)stop;
    ((Model *)c)->t = start;
    return OK;
}

int fmi2EnterInitializationMode(void *c) { (void)c; return OK; }
int fmi2ExitInitializationMode(void *c) { outputs(c); return OK; }
int fmi2Terminate(void *c) { (void)c; return OK; }
int fmi2Reset(void *c) { reset(c); return OK; }

int fmi2GetReal(void *c, const unsigned *vr, size_t n, double *value) {
    Model *m = c;
    outputs(m);
    for (size_t i = 0; i < n; i++) {
        switch (vr[i]) {
        case 0: value[i] = m->y; break;
        case 1: value[i] = m->u; break;
        case 2: value[i] = m->gain; break;
        default: return ERROR;
        }
    }
    return OK;
}

int fmi2SetReal(void *c, const unsigned *vr, size_t n, const double *value) {
    Model *m = c;
    for (size_t i = 0; i < n; i++) {
        switch (vr[i]) {
        case 1: m->u = value[i]; break;
        case 2: m->gain = value[i]; break;
        default: return ERROR;
        }
    }
    return OK;
}

int fmi2GetInteger(void *c, const unsigned *vr, size_t n, int *value) {
    Model *m = c;
    outputs(m);
    for (size_t i = 0; i < n; i++) {
        switch (vr[i]) {
        case 0: value[i] = m->n; break;
        case 1: value[i] = m->k; break;
        case 2: value[i] = m->count; break;
        default: return ERROR;
        }
    }
    return OK;
}

int fmi2SetInteger(void *c, const unsigned *vr, size_t n, const int *value) {
    Model *m = c;
    for (size_t i = 0; i < n; i++) {
        switch (vr[i]) {
        case 1: m->k = value[i]; break;
        case 2: m->count = value[i]; break;
        default: return ERROR;
        }
    }
    return OK;
}

int fmi2GetBoolean(void *c, const unsigned *vr, size_t n, int *value) {
    Model *m = c;
    outputs(m);
    for (size_t i = 0; i < n; i++) {
        switch (vr[i]) {
        case 0: value[i] = m->b; break;
        case 1: value[i] = m->on; break;
        case 2: value[i] = m->flag; break;
        default: return ERROR;
        }
    }
    return OK;
}

int fmi2SetBoolean(void *c, const unsigned *vr, size_t n, const int *value) {
    Model *m = c;
    for (size_t i = 0; i < n; i++) {
        switch (vr[i]) {
        case 1: m->on = value[i] != 0; break;
        case 2: m->flag = value[i] != 0; break;
        default: return ERROR;
        }
    }
    return OK;
}

int fmi2GetString(void *c, const unsigned *vr, size_t n, const char **v) {
    (void)c; (void)vr; (void)v;
    return n ? ERROR : OK;
}
int fmi2SetString(void *c, const unsigned *vr, size_t n, const char *const *v) {
    (void)c; (void)vr; (void)v;
    return n ? ERROR : OK;
}

int fmi2DoStep(void *c, double t, double h, int no_prior) {
    Model *m = c;
    (void)no_prior;
    m->t = t + h;
    m->steps += 1;
    outputs(m);
    return OK;
}

