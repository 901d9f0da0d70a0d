/*
 * signal_source.c - ScenarioSignals, the signal source of an SSP package (latobs export-ssp): a
 * validation scenario's input signals, sampled on a uniform time grid at build time, played back
 * as outputs with a zero-order hold. Model declaration: fmu_src/models/signal_source.py; data:
 * model_data.h from latobs/cbackend/signal_source.py. C99, libc and libm only.
 *
 * model_data.h: SS_T0 (s, the first sample's time), SS_DT (s, the grid's step), SS_N_ROWS and
 * SS_TABLE[SS_N_ROWS][N_OUTPUTS] (row k: every signal at SS_T0 + k SS_DT).
 *
 * The outputs at time t are the row at or before t, k = floor((t - SS_T0) / SS_DT + 1e-6) (the
 * 1e-6 absorbs a host's round-off in t), clamped to [0, SS_N_ROWS - 1]: the first row before the
 * grid, the last one after it. t is the start time at initialisation and, after a step, the
 * communication point the step started from plus its length (the layer gives both: layer_time),
 * so that the signal source outputs after its step from t_k the sample of t_(k+1): the Jacobi
 * ordering of the harness. No inputs, no parameters; a step whose end time is not finite is
 * refused (error, outputs held). Co-simulation only.
 */
#include <math.h>

#include "model.h"
#include "model_data.h"

#if N_STATES != 0 || N_INPUTS != 0
#error "the signal source has neither states nor inputs"
#endif

struct Model {
    long row; /* the row of SS_TABLE the outputs hold */
};

size_t model_size(void)
{
    return sizeof(Model);
}

/* the row at or before time t (s), clamped to the table */
static long row_at(double t)
{
    double k = floor((t - SS_T0) / SS_DT + 1e-6);
    if (!(k > 0.0)) return 0;
    if (k >= (double)(SS_N_ROWS - 1)) return SS_N_ROWS - 1;
    return (long)k;
}

int model_setup(Model *m, const double *p, const Log *log)
{
    (void)p;
    m->row = row_at(layer_time(log));
    return 0;
}

void model_initialize(Model *m, const double *u, const Log *log)
{
    (void)m, (void)u, (void)log; /* no inputs: the outputs are the start time's row */
}

int model_do_step(Model *m, double h, const double *u, const Log *log)
{
    double t = layer_time(log) + h;
    (void)u;
    if (!isfinite(t)) {
        log_event(log, LOG_ERROR, "step refused: the step of %g s from t = %g s ends at a time that is not finite",
                  h, layer_time(log));
        return -1;
    }
    m->row = row_at(t);
    return 0;
}

void model_outputs(const Model *m, double *y, int *yi)
{
    (void)yi;
    for (int i = 0; i < N_OUTPUTS; i++) y[i] = SS_TABLE[m->row][i];
}
