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

FMI2_SETUP_TAKES_START(Model)

int fmi2EnterInitializationMode(void *c) { (void)c; return OK; }
int fmi2ExitInitializationMode(void *c) { outputs(c); return OK; }
int fmi2Terminate(void *c) { (void)c; return OK; }
int fmi2Reset(void *c) { reset(c); return OK; }

/* Value reference 0 is an output, 1 an input, 2 a parameter (of each type). */
static int input_or_parameter(unsigned vr) { return vr == 1 || vr == 2; }

FMI2_FIELDS(Real, double, Model, outputs, input_or_parameter, FMI2_AS_IS, &m->y, &m->u, &m->gain)
FMI2_FIELDS(Integer, int, Model, outputs, input_or_parameter, FMI2_AS_IS, &m->n, &m->k, &m->count)
FMI2_FIELDS(Boolean, int, Model, outputs, input_or_parameter, FMI2_TRUTH, &m->b, &m->on, &m->flag)
FMI2_NO_VARIABLES(String, fmi2_string)

int fmi2DoStep(void *c, double t, double h, int no_prior) {
    Model *m = c;
    (void)no_prior;
    m->t = t + h;
    m->steps += 1;
    outputs(m);
    return OK;
}

