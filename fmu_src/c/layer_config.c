/*
 * layer_config.c - LAYER_CONFIG (layer_config.h): the FMU's sizes (its generated fmu_config.h) and
 * its identifiers, token and variable tables (its generated fmu_tables.h), for the FMI layer, which
 * is compiled without them. No maths here.
 * For a co-simulation-only model (no states) it also defines the model exchange functions of
 * model.h, never called (the layers refuse a ModelExchange instance of such an FMU), so that the
 * same layer object links with every model.
 */
#include "model.h"

#include "fmu_tables.h"
#include "layer_config.h"

/* compile-time checks (C99: an array of negative size is an error): the layer's buffers fit */
typedef char layer_config_vars_fit[(N_PARAMETERS <= LAYER_MAX_VARS && N_INPUTS <= LAYER_MAX_VARS &&
                                    N_OUTPUTS <= LAYER_MAX_VARS && N_INT_OUTPUTS <= LAYER_MAX_VARS) ? 1 : -1];
typedef char layer_config_states_fit[(N_STATES <= LAYER_MAX_STATES &&
                                      N_EVENT_INDICATORS <= LAYER_MAX_EVENT_INDICATORS) ? 1 : -1];

#ifndef N_ARRAYS /* an FMI 2.0 FMU: no gain arrays */
#define N_ARRAYS 0
static const char *const ARR_NAMES[] = {0};
static const int ARR_OFFSET[1] = {0};
static const int ARR_SIZE[1] = {0};
static const double ARR_VALUES[1] = {0.0};
#endif

const LayerConfig LAYER_CONFIG = {
    MODEL_IDENTIFIER, INSTANTIATION_TOKEN,
    N_PARAMETERS, N_INPUTS, N_OUTPUTS, N_INT_OUTPUTS, N_STATES, N_EVENT_INDICATORS,
    MAX_STEP, MAX_STEP_REFUSED_ABOVE,
    VAR_NAMES,
    PAR_START, PAR_MIN, PAR_MAX, IN_START, IN_MIN, IN_MAX, OUT_START,
    INT_START,
    N_ARRAYS, ARR_NAMES, ARR_OFFSET, ARR_SIZE, ARR_VALUES,
};

#if N_STATES == 0
void model_me_get_states(const Model *m, double *x) { (void)m, (void)x; }
void model_me_set_states(Model *m, const double *x) { (void)m, (void)x; }
void model_me_nominals(const Model *m, double *nominal) { (void)m, (void)nominal; }
void model_me_derivatives(const Model *m, const double *u, double *dx) { (void)m, (void)u, (void)dx; }
void model_me_event_indicators(const Model *m, const double *u, double *z) { (void)m, (void)u, (void)z; }
int model_me_event_update(Model *m, double t, const double *u, const Log *log)
{
    (void)m, (void)t, (void)u, (void)log;
    return 0;
}
void model_me_outputs(const Model *m, const double *u, double *y, int *yi) { (void)m, (void)u, (void)y, (void)yi; }
#endif
