/* An FMI 2.0 Co-Simulation FMU with an internal variable-step solver, as many exporting
 * tools build them: the Van der Pol oscillator
 *     x1' = x2,  x2' = mu (1 - x1^2) x2 - x1
 * integrated inside fmi2DoStep by an embedded Runge-Kutta 2(3) pair (Bogacki-Shampine) with
 * step size control. Its accuracy follows the tolerance the importer passes to
 * fmi2SetupExperiment (toleranceDefined); without one it uses its own coarse default 1e-2.
 * Built by the test suite with gcc.
 *
 *   value references (Real): 0 x1 (output), 1 x2 (output), 2 mu (parameter, 1.0),
 *                            3 steps_taken (output: internal steps so far)
 *
 * Only the C types are used (no FMI headers). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2_common.h"

typedef struct {
    double x1, x2, mu, t, rtol, dt, steps;
} Model;

static void reset(Model *m) {
    memset(m, 0, sizeof(Model));
    m->x1 = 2.0;
    m->mu = 1.0;
    m->rtol = 1e-2;
}

static void f(const Model *m, const double x[2], double dx[2]) {
    dx[0] = x[1];
    dx[1] = m->mu * (1.0 - x[0] * x[0]) * x[1] - x[0];
}

/* From t to t + h with error control; the last accepted internal step is remembered. */
static void integrate(Model *m, double h) {
    double x[2] = {m->x1, m->x2}, t = 0.0;
    double dt = m->dt > 0.0 ? m->dt : h / 10.0;
    const double atol = m->rtol * 1e-2;
    double k1[2], k2[2], k3[2], k4[2], y[2], z[2], xs[2];
    f(m, x, k1);
    while (t < h) {
        int last = 0;
        if (t + dt >= h) {
            dt = h - t;
            last = 1;
        }
        for (int i = 0; i < 2; i++) xs[i] = x[i] + 0.5 * dt * k1[i];
        f(m, xs, k2);
        for (int i = 0; i < 2; i++) xs[i] = x[i] + 0.75 * dt * k2[i];
        f(m, xs, k3);
        for (int i = 0; i < 2; i++) y[i] = x[i] + dt * (2.0 / 9 * k1[i] + 1.0 / 3 * k2[i] + 4.0 / 9 * k3[i]);
        f(m, y, k4);
        double err = 0.0;
        for (int i = 0; i < 2; i++) {
            z[i] = x[i] + dt * (7.0 / 24 * k1[i] + 0.25 * k2[i] + 1.0 / 3 * k3[i] + 0.125 * k4[i]);
            double sc = atol + m->rtol * fmax(fabs(x[i]), fabs(y[i]));
            double e = (y[i] - z[i]) / sc;
            err += e * e;
        }
        err = sqrt(err / 2.0);
        if (err <= 1.0) {
            t = last ? h : t + dt;
            x[0] = y[0];
            x[1] = y[1];
            k1[0] = k4[0];
            k1[1] = k4[1];
            m->steps += 1.0;
            if (!last)
                m->dt = dt;
        }
        double factor = err > 0.0 ? 0.9 * pow(err, -1.0 / 3.0) : 5.0;
        dt *= fmin(5.0, fmax(0.2, factor));
        if (last && err > 1.0)
            continue;
        if (last && err <= 1.0)
            break;
    }
    m->x1 = x[0];
    m->x2 = x[1];
}

FMI2_MODEL_INSTANCE(Model, reset)

int fmi2SetupExperiment(void *c, int tol_defined, double tol, double start, int stop_defined,
                        double stop) {
    Model *m = c;
    (void)stop_defined; (void)stop;
    m->t = start;
    if (tol_defined) {
        if (!(tol > 0.0 && tol < 1.0))
            return ERROR;
        m->rtol = tol;
    }
    return OK;
}

int fmi2EnterInitializationMode(void *c) { (void)c; return OK; }
int fmi2ExitInitializationMode(void *c) { (void)c; return OK; }
int fmi2Terminate(void *c) { (void)c; return OK; }
int fmi2Reset(void *c) { reset(c); return OK; }

/* Only mu (value reference 2) is set. */
static int is_mu(unsigned vr) { return vr == 2; }

FMI2_FIELDS(Real, double, Model, FMI2_NO_UPDATE, is_mu, FMI2_AS_IS, &m->x1, &m->x2, &m->mu, &m->steps)
FMI2_NO_VARIABLES(Integer, int)
FMI2_NO_VARIABLES(Boolean, int)
FMI2_NO_VARIABLES(String, fmi2_string)

int fmi2DoStep(void *c, double t, double h, int no_prior) {
    Model *m = c;
    (void)no_prior;
    if (!(h > 0.0))
        return ERROR;
    integrate(m, h);
    m->t = t + h;
    return OK;
}

