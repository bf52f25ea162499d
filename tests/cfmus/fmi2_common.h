/* What the C test FMUs of this folder share (C types only, no FMI headers): the status codes
 * they return, the platform and version queries, debug logging that is accepted and
 * ignored, the getters and setters of variables that are fields of the model (or of no
 * variables), and the optional functions none of them provides, present so that every
 * importer finds its symbols; each of those returns fmi2Error.
 *
 * Define FMI2_MODEL_EXCHANGE before including it in a Model Exchange FMU: the
 * Co-Simulation functions are then left out. */
#ifndef TWINBENCH_TEST_FMI2_COMMON_H
#define TWINBENCH_TEST_FMI2_COMMON_H

#include <stddef.h>

enum { OK = 0, ERROR = 3 };

const char *fmi2GetTypesPlatform(void) { return "default"; }
const char *fmi2GetVersion(void) { return "2.0"; }

int fmi2SetDebugLogging(void *c, int on, size_t n, const char *const cats[]) {
    (void)c; (void)on; (void)n; (void)cats;
    return OK;
}

int fmi2GetFMUstate(void *c, void **s) { (void)c; (void)s; return ERROR; }
int fmi2SetFMUstate(void *c, void *s) { (void)c; (void)s; return ERROR; }
int fmi2FreeFMUstate(void *c, void **s) { (void)c; (void)s; return ERROR; }
int fmi2SerializedFMUstateSize(void *c, void *s, size_t *n) { (void)c; (void)s; (void)n; return ERROR; }
int fmi2SerializeFMUstate(void *c, void *s, char *b, size_t n) { (void)c; (void)s; (void)b; (void)n; return ERROR; }
int fmi2DeSerializeFMUstate(void *c, const char *b, size_t n, void **s) { (void)c; (void)b; (void)n; (void)s; return ERROR; }
int fmi2GetDirectionalDerivative(void *c, const unsigned *u, size_t nu, const unsigned *z, size_t nz,
                                 const double *dz, double *du) {
    (void)c; (void)u; (void)nu; (void)z; (void)nz; (void)dz; (void)du;
    return ERROR;
}

/* fmi2Instantiate and fmi2FreeInstance of an FMU whose instance is one zeroed `Model` set up
 * by `reset` (a function of the Model): expanded after both are defined. */
#define FMI2_MODEL_INSTANCE(Model, reset)                                                       \
    void *fmi2Instantiate(const char *name, int type, const char *guid, const char *resources, \
                          const void *callbacks, int visible, int logging) {                   \
        (void)name; (void)type; (void)guid; (void)resources; (void)callbacks; (void)visible;   \
        (void)logging;                                                                          \
        Model *m = calloc(1, sizeof(Model));                                                    \
        if (m)                                                                                  \
            reset(m);                                                                           \
        return m;                                                                               \
    }                                                                                           \
    void fmi2FreeInstance(void *c) { free(c); }

/* fmi2SetupExperiment of an FMU whose `Model` keeps the time in its field t: the start
 * time is taken, the tolerance and the stop time are not used. */
#define FMI2_SETUP_TAKES_START(Model)                                                 \
    int fmi2SetupExperiment(void *c, int tol_defined, double tol, double start,      \
                            int stop_defined, double stop) {                          \
        (void)tol_defined; (void)tol; (void)stop_defined; (void)stop;                 \
        ((Model *)c)->t = start;                                                      \
        return OK;                                                                    \
    }

typedef const char *fmi2_string;

/* fmi2Get<Type> and fmi2Set<Type> of an FMU without variables of that type: only a request
 * for no value succeeds. */
#define FMI2_NO_VARIABLES(Type, T)                                                  \
    int fmi2Get##Type(void *c, const unsigned *vr, size_t n, T *v) {                \
        (void)c; (void)vr; (void)v;                                                 \
        return n ? ERROR : OK;                                                      \
    }                                                                               \
    int fmi2Set##Type(void *c, const unsigned *vr, size_t n, const T *v) {          \
        (void)c; (void)vr; (void)v;                                                 \
        return n ? ERROR : OK;                                                      \
    }

/* What fmi2Set<Type> stores of a value: the value, or (Boolean) whether it is not 0. */
#define FMI2_AS_IS(v) (v)
#define FMI2_TRUTH(v) ((v) != 0)

/* fmi2Get<Type> and fmi2Set<Type> of the variables of C type T that are fields of a `Model
 * *m`: the last arguments are their addresses (`&m->x`), in the order of their value
 * references 0, 1, 2 ... Before a get, `update(m)` brings the fields up to date
 * (FMI2_NO_UPDATE: nothing to do); a set of value reference vr needs `settable(vr)` and
 * stores `stored(value)`. An unknown value reference is an error (the values before it
 * are taken). */
#define FMI2_NO_UPDATE(m) (void)(m)
#define FMI2_FIELDS(Type, T, Model, update, settable, stored, ...)                  \
    int fmi2Get##Type(void *c, const unsigned *vr, size_t n, T *value) {            \
        Model *m = c;                                                               \
        update(m);                                                                  \
        T *field[] = {__VA_ARGS__};                                                 \
        for (size_t i = 0; i < n; i++) {                                            \
            if (vr[i] >= sizeof field / sizeof field[0])                            \
                return ERROR;                                                       \
            value[i] = *field[vr[i]];                                               \
        }                                                                           \
        return OK;                                                                  \
    }                                                                               \
    int fmi2Set##Type(void *c, const unsigned *vr, size_t n, const T *value) {      \
        Model *m = c;                                                               \
        T *field[] = {__VA_ARGS__};                                                 \
        for (size_t i = 0; i < n; i++) {                                            \
            if (vr[i] >= sizeof field / sizeof field[0] || !settable(vr[i]))        \
                return ERROR;                                                       \
            *field[vr[i]] = stored(value[i]);                                       \
        }                                                                           \
        return OK;                                                                  \
    }

#ifndef FMI2_MODEL_EXCHANGE
int fmi2CancelStep(void *c) { (void)c; return ERROR; }
int fmi2GetStatus(void *c, int s, int *v) { (void)c; (void)s; (void)v; return ERROR; }
int fmi2GetRealStatus(void *c, int s, double *v) { (void)c; (void)s; (void)v; return ERROR; }
int fmi2GetIntegerStatus(void *c, int s, int *v) { (void)c; (void)s; (void)v; return ERROR; }
int fmi2GetBooleanStatus(void *c, int s, int *v) { (void)c; (void)s; (void)v; return ERROR; }
int fmi2GetStringStatus(void *c, int s, const char **v) { (void)c; (void)s; (void)v; return ERROR; }
int fmi2SetRealInputDerivatives(void *c, const unsigned *vr, size_t n, const int *o, const double *v) {
    (void)c; (void)vr; (void)n; (void)o; (void)v;
    return ERROR;
}
int fmi2GetRealOutputDerivatives(void *c, const unsigned *vr, size_t n, const int *o, double *v) {
    (void)c; (void)vr; (void)n; (void)o; (void)v;
    return ERROR;
}
#endif

#endif
