/* A deliberately hostile FMI 2.0 Co-Simulation FMU, written for twinbench's isolation
 * tests and built by the test suite with gcc. Its model is trivial: an output y that
 * follows the input u. The fault is chosen when compiling, with -DFAULT=<name>:
 *
 *   NONE          behaves
 *   LOAD_EXIT     exit(0) while the library is being loaded (a constructor)
 *   VERSION_NULL  fmi2GetVersion returns NULL
 *   VERSION_SEGV  fmi2GetVersion dereferences NULL
 *   VERSION_HANG  fmi2GetVersion never returns
 *   VERSION_EXIT  fmi2GetVersion calls exit(0)
 *   STEP_SEGV     fmi2DoStep dereferences NULL at t >= 0.5 s
 *   STEP_HANG     fmi2DoStep never returns at t >= 0.5 s
 *   STEP_EXIT     fmi2DoStep calls exit(0) at t >= 0.5 s
 *   STEP_FLOOD    fmi2DoStep writes to stderr without end, and no newline, at t >= 0.5 s
 *   STDOUT_JSON   fmi2Instantiate prints a forged JSON document to stdout
 *   KILL_PARENT   fmi2DoStep sends SIGKILL to its parent process at t >= 0.5 s, once
 *
 * Only the C types are used (no FMI headers): the functions keep the standard's
 * signatures, with fmi2Component = void*, fmi2Status = int, fmi2Boolean = int. */
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <signal.h>
#include <stdio.h>

#define NONE 0
#define LOAD_EXIT 1
#define VERSION_NULL 2
#define VERSION_SEGV 3
#define VERSION_HANG 4
#define VERSION_EXIT 5
#define STEP_SEGV 6
#define STEP_HANG 7
#define STEP_EXIT 8
#define STEP_FLOOD 9
#define STDOUT_JSON 10
#define KILL_PARENT 11

#ifndef FAULT
#define FAULT NONE
#endif

enum { OK = 0, ERROR = 3 };
enum { VR_U = 0, VR_Y = 1 };

typedef struct {
    double u, y, t;
} Model;

__attribute__((unused)) static void crash(void) {
    volatile int *volatile p = NULL;
    *p = 1;
}

__attribute__((unused)) static void hang(void) {
    for (;;)
        pause();
}

__attribute__((unused)) static void flood(void) {
    char text[4096];
    memset(text, 'x', sizeof text);
    for (;;)
        if (write(2, text, sizeof text) < 0)
            hang();
}

#if FAULT == LOAD_EXIT
__attribute__((constructor)) static void on_load(void) { exit(0); }
#endif

const char *fmi2GetTypesPlatform(void) { return "default"; }

const char *fmi2GetVersion(void) {
#if FAULT == VERSION_NULL
    return NULL;
#elif FAULT == VERSION_SEGV
    crash();
#elif FAULT == VERSION_HANG
    hang();
#elif FAULT == VERSION_EXIT
    exit(0);
#endif
    return "2.0";
}

int fmi2SetDebugLogging(void *c, int on, size_t n, const char *const cats[]) {
    (void)c; (void)on; (void)n; (void)cats;
    return OK;
}

void *fmi2Instantiate(const char *name, int type, const char *guid, const char *resources,
                      const void *callbacks, int visible, int logging) {
    (void)name; (void)type; (void)guid; (void)resources; (void)callbacks; (void)visible;
    (void)logging;
    Model *m = calloc(1, sizeof(Model));
    if (m)
        m->u = 1.0; /* the start value in the model description */
#if FAULT == STDOUT_JSON
    printf("{\"lap_time\": 1.0}\n");
    fflush(stdout);
#endif
    return m;
}

void fmi2FreeInstance(void *c) { free(c); }

int fmi2SetupExperiment(void *c, int tol_defined, double tol, double start, int stop_defined,
                        double stop) {
    (void)tol_defined; (void)tol; (void)stop_defined; (void)stop;
    ((Model *)c)->t = start;
    return OK;
}

int fmi2EnterInitializationMode(void *c) { (void)c; return OK; }
int fmi2ExitInitializationMode(void *c) { Model *m = c; m->y = m->u; return OK; }
int fmi2Terminate(void *c) { (void)c; return OK; }
int fmi2Reset(void *c) {
    Model *m = c;
    memset(m, 0, sizeof(Model));
    m->u = 1.0;
    return OK;
}

int fmi2GetReal(void *c, const unsigned *vr, size_t n, double *value) {
    Model *m = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == VR_U) value[i] = m->u;
        else if (vr[i] == VR_Y) value[i] = m->y;
        else return ERROR;
    }
    return OK;
}

int fmi2SetReal(void *c, const unsigned *vr, size_t n, const double *value) {
    Model *m = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != VR_U) return ERROR;
        m->u = value[i];
    }
    return OK;
}

int fmi2GetInteger(void *c, const unsigned *vr, size_t n, int *v) { (void)c; (void)vr; (void)v; return n ? ERROR : OK; }
int fmi2SetInteger(void *c, const unsigned *vr, size_t n, const int *v) { (void)c; (void)vr; (void)v; return n ? ERROR : OK; }
int fmi2GetBoolean(void *c, const unsigned *vr, size_t n, int *v) { (void)c; (void)vr; (void)v; return n ? ERROR : OK; }
int fmi2SetBoolean(void *c, const unsigned *vr, size_t n, const int *v) { (void)c; (void)vr; (void)v; return n ? ERROR : OK; }
int fmi2GetString(void *c, const unsigned *vr, size_t n, const char **v) { (void)c; (void)vr; (void)v; return n ? ERROR : OK; }
int fmi2SetString(void *c, const unsigned *vr, size_t n, const char *const *v) { (void)c; (void)vr; (void)v; return n ? ERROR : OK; }

int fmi2DoStep(void *c, double t, double h, int no_prior) {
    Model *m = c;
    (void)no_prior;
    if (t >= 0.5) {
#if FAULT == STEP_SEGV
        crash();
#elif FAULT == STEP_HANG
        hang();
#elif FAULT == STEP_EXIT
        exit(0);
#elif FAULT == STEP_FLOOD
        flood();
#elif FAULT == KILL_PARENT
        static int killed = 0;
        if (!killed) {
            killed = 1;
            kill(getppid(), SIGKILL);
        }
#endif
    }
    m->y = m->u;
    m->t = t + h;
    return OK;
}
