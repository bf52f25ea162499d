/* What the C test FMUs of this folder share (C types only, no FMI headers): the status codes
 * they return, the platform and version queries, debug logging that is accepted and
 * ignored, and the optional functions none of them provides, present so that every
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
