/*
 * layer_config.h - what an FMI layer (fmi2_layer.c, fmi3_layer.c) knows of the FMU it serves: one
 * constant, LAYER_CONFIG, defined by layer_config.c from the FMU's generated fmu_config.h and
 * fmu_tables.h. The
 * layers read the FMU's sizes, tables and token from it at run time, so a layer's object file is
 * the same for every FMU and is compiled once per platform (latobs.cbackend.toolchain); the model
 * file keeps the compile-time constants of fmu_config.h.
 *
 * A layer defines LATOBS_LAYER before including model.h (which then leaves fmu_config.h out) and
 * this file gives it the names of those headers (N_INPUTS, IN_MIN, INSTANTIATION_TOKEN, ...) as
 * reads of LAYER_CONFIG. Its fixed-size buffers hold up to LAYER_MAX_VARS values of each group,
 * LAYER_MAX_STATES states and LAYER_MAX_EVENT_INDICATORS event indicators (layer_config.c refuses
 * to compile an FMU with more).
 */
#ifndef LATOBS_LAYER_CONFIG_H
#define LATOBS_LAYER_CONFIG_H

#define LAYER_MAX_VARS 64
#define LAYER_MAX_STATES 32
#define LAYER_MAX_EVENT_INDICATORS 64

typedef struct {
    const char *model_identifier;
    const char *token; /* the guid (FMI 2.0) or instantiation token (FMI 3.0) */
    long n_parameters, n_inputs, n_outputs, n_int_outputs, n_states, n_event_indicators;
    double max_step;               /* s, the longest communication step, as declared */
    double max_step_refused_above; /* s, with its slack */
    const char *const *var_names;  /* by value reference, through the derivatives */
    const double *par_start, *par_min, *par_max, *in_start, *in_min, *in_max, *out_start;
    const int *int_start;
    /* the FMI 3.0 layer's gain arrays (constants; none in an FMI 2.0 FMU) */
    long n_arrays;
    const char *const *arr_names;
    const int *arr_offset, *arr_size;
    const double *arr_values;
} LayerConfig;

extern const LayerConfig LAYER_CONFIG;

#ifdef LATOBS_LAYER
#define MODEL_IDENTIFIER (LAYER_CONFIG.model_identifier)
#define INSTANTIATION_TOKEN (LAYER_CONFIG.token)
#define N_PARAMETERS (LAYER_CONFIG.n_parameters)
#define N_INPUTS (LAYER_CONFIG.n_inputs)
#define N_OUTPUTS (LAYER_CONFIG.n_outputs)
#define N_INT_OUTPUTS (LAYER_CONFIG.n_int_outputs)
#define N_STATES (LAYER_CONFIG.n_states)
#define N_EVENT_INDICATORS (LAYER_CONFIG.n_event_indicators)
#define MAX_STEP (LAYER_CONFIG.max_step)
#define MAX_STEP_REFUSED_ABOVE (LAYER_CONFIG.max_step_refused_above)
#define VAR_NAMES (LAYER_CONFIG.var_names)
#define PAR_START (LAYER_CONFIG.par_start)
#define PAR_MIN (LAYER_CONFIG.par_min)
#define PAR_MAX (LAYER_CONFIG.par_max)
#define IN_START (LAYER_CONFIG.in_start)
#define IN_MIN (LAYER_CONFIG.in_min)
#define IN_MAX (LAYER_CONFIG.in_max)
#define OUT_START (LAYER_CONFIG.out_start)
#define INT_START (LAYER_CONFIG.int_start)
#define N_ARRAYS (LAYER_CONFIG.n_arrays)
#define ARR_NAMES (LAYER_CONFIG.arr_names)
#define ARR_OFFSET (LAYER_CONFIG.arr_offset)
#define ARR_SIZE (LAYER_CONFIG.arr_size)
#define ARR_VALUES (LAYER_CONFIG.arr_values)
#endif

#endif
