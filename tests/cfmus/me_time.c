/* An FMI 2.0 Model Exchange FMU for the time handling of twinbench's integrator (red team
 * M5-M7): x' = -x, x(0) = 1, output y = x, and a time event whose time the parameter
 * `mode` chooses:
 *
 *   0  none
 *   1  nextEventTime = 0 s, whatever the time (in the past for a run that starts later: M5)
 *   2  nextEventTime = +inf (no event: M6)
 *   3  nextEventTime = -inf (not a time)
 *   4  der(x) is NaN after 0.5 s (M17: named, not only CVODE's "t + h = t")
 *   5  the event indicator is NaN after 0.5 s (M17: an error, not a missed event)
 *
 *   one event indicator, x + 1, which never crosses zero (x decays from 1)
 *
 *   value references: Real 0 x (state), 1 der(x), 2 y (output); Integer 3 mode (parameter);
 *                     Real 4 events (output: events handled)
 *
 * Built by the test suite with gcc. Only the C types are used (no FMI headers). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define FMI2_MODEL_EXCHANGE
#include "fmi2_common.h"

typedef struct {
    double x, t, events;
    int mode;
} Model;

typedef struct {
    int newDiscreteStatesNeeded, terminateSimulation, nominalsOfContinuousStatesChanged,
        valuesOfContinuousStatesChanged, nextEventTimeDefined;
    double nextEventTime;
} EventInfo;

void *fmi2Instantiate(const char *name, int type, const char *guid, const char *res,
                      const void *cb, int visible, int logging) {
    (void)name; (void)type; (void)guid; (void)res; (void)cb; (void)visible; (void)logging;
    Model *m = calloc(1, sizeof(Model));
    if (m) m->x = 1.0;
    return m;
}
void fmi2FreeInstance(void *c) { free(c); }
FMI2_SETUP_TAKES_START(Model)
int fmi2EnterInitializationMode(void *c) { (void)c; return OK; }
int fmi2ExitInitializationMode(void *c) { (void)c; return OK; }
int fmi2Terminate(void *c) { (void)c; return OK; }
int fmi2Reset(void *c) { Model *m = c; int mode = m->mode; memset(m, 0, sizeof *m); m->x = 1.0; m->mode = mode; return OK; }
int fmi2GetReal(void *c, const unsigned *vr, size_t n, double *v) {
    Model *m = c;
    for (size_t k = 0; k < n; k++) {
        switch (vr[k]) {
        case 0: case 2: v[k] = m->x; break;
        case 1: v[k] = m->mode == 4 && m->t > 0.5 ? NAN : -m->x; break;
        case 4: v[k] = m->events; break;
        default: return ERROR;
        }
    }
    return OK;
}
int fmi2SetReal(void *c, const unsigned *vr, size_t n, const double *v) {
    Model *m = c;
    for (size_t k = 0; k < n; k++) {
        if (vr[k] != 0) return ERROR;
        m->x = v[k];
    }
    return OK;
}
int fmi2GetInteger(void *c, const unsigned *vr, size_t n, int *v) {
    Model *m = c;
    for (size_t k = 0; k < n; k++) { if (vr[k] != 3) return ERROR; v[k] = m->mode; }
    return OK;
}
int fmi2SetInteger(void *c, const unsigned *vr, size_t n, const int *v) {
    Model *m = c;
    for (size_t k = 0; k < n; k++) { if (vr[k] != 3) return ERROR; m->mode = v[k]; }
    return OK;
}
FMI2_NO_VARIABLES(Boolean, int)
FMI2_NO_VARIABLES(String, fmi2_string)
int fmi2EnterEventMode(void *c) { (void)c; return OK; }
int fmi2NewDiscreteStates(void *c, EventInfo *e) {
    Model *m = c;
    memset(e, 0, sizeof *e);
    m->events += 1;
    switch (m->mode) {
    case 1: e->nextEventTimeDefined = 1; e->nextEventTime = 0.0; break;
    case 2: e->nextEventTimeDefined = 1; e->nextEventTime = INFINITY; break;
    case 3: e->nextEventTimeDefined = 1; e->nextEventTime = -INFINITY; break;
    default: break;
    }
    return OK;
}
int fmi2EnterContinuousTimeMode(void *c) { (void)c; return OK; }
int fmi2CompletedIntegratorStep(void *c, int noSet, int *enter, int *term) {
    (void)c; (void)noSet; *enter = 0; *term = 0; return OK;
}
int fmi2SetTime(void *c, double t) { Model *m = c; m->t = t; return OK; }
int fmi2SetContinuousStates(void *c, const double *x, size_t n) { Model *m = c; if (n != 1) return ERROR; m->x = x[0]; return OK; }
int fmi2GetDerivatives(void *c, double *dx, size_t n) {
    Model *m = c; if (n != 1) return ERROR;
    dx[0] = m->mode == 4 && m->t > 0.5 ? NAN : -m->x;
    return OK;
}
int fmi2GetEventIndicators(void *c, double *z, size_t n) {
    Model *m = c; if (n != 1) return ERROR;
    z[0] = m->mode == 5 && m->t > 0.5 ? NAN : m->x + 1.0;
    return OK;
}
int fmi2GetContinuousStates(void *c, double *x, size_t n) { Model *m = c; if (n != 1) return ERROR; x[0] = m->x; return OK; }
int fmi2GetNominalsOfContinuousStates(void *c, double *x, size_t n) { (void)c; for (size_t i = 0; i < n; i++) x[i] = 1.0; return OK; }
