/*
 * model.h - the interface between the shared FMI layers (fmi2_layer.c, fmi3_layer.c) and a model file
 * (<runtime>.c), in the manner of the Reference FMUs: the layer holds the FMI state machine,
 * the variable table, logging and the statuses and knows no maths; a model file holds the maths
 * and knows nothing of FMI. C99, libc and libm only.
 *
 * Generated per FMU at build time (latobs.cbackend):
 *   fmu_config.h  the variable table's sizes and indices (no identifier or guid: the same for
 *                 both FMI versions):
 *                 N_PARAMETERS, N_INPUTS, N_OUTPUTS (Real), N_INT_OUTPUTS, N_STATES (ModelExchange
 *                 continuous states, 0 = co-simulation only), N_EVENT_INDICATORS, and one index
 *                 macro per variable in the order of the model file's ModelSpec:
 *                 PAR_<name>, IN_<name>, OUT_<name>, INT_<name> (0-based within its group);
 *                 MAX_STEP (s, the ModelSpec's max_step). The layers do not include it: they
 *                 read it through LAYER_CONFIG (layer_config.h), so that one compiled layer
 *                 serves every FMU.
 *   fmu_tables.h  for layer_config.c only: identifiers, guid, the variables' names, start
 *                 values and declared [min, max].
 *   model_data.h  the design (certified gains, discretisation, tables) as static const data,
 *                 written by the model's emitter (latobs/cbackend/<runtime>.py); included by the
 *                 model file only.
 *
 * Every function below receives only inputs inside their declared [min, max] (IN_MIN, IN_MAX of
 * fmu_config.h, from the ModelSpec: finite) and (for model_do_step) 0 < h <= the model's longest
 * step (MAX_STEP, plus a relative slack of 1e-9): the layer refuses the others with fmi2Error
 * before calling. A model function never aborts, never
 * allocates after model_setup, and reports through the Log:
 *   log_event(log, LOG_WARNING, "...")   clamps, excursions (the layer returns fmi2Warning)
 *   log_event(log, LOG_ERROR, "...")     a refused call (with a nonzero return)
 */
#ifndef LATOBS_MODEL_H
#define LATOBS_MODEL_H

#include "fp_contract.h" /* first: no FMA contraction, whatever the compiler's flags */

#include <stddef.h>

#ifndef LATOBS_LAYER /* the layers read the FMU's configuration at run time: layer_config.h */
#include "fmu_config.h"
#endif

#define LOG_INFO 0
#define LOG_WARNING 1
#define LOG_ERROR 3

typedef struct Log Log;   /* the layer's; opaque to the model */

/* printf-like; the message is logged by the host's logger under logStatusWarning / logStatusError /
 * logAll. Implemented by the layer. */
void log_event(const Log *log, int level, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

/* The time (s) of the model call in progress: in model_setup and model_initialize the start
 * time (fmi2SetupExperiment's, else 0), in model_do_step the communication point the step starts
 * from (fmi2DoStep's currentCommunicationPoint). For models whose maths depends on absolute time
 * (the SSP signal source's tables); implemented by the layer. */
double layer_time(const Log *log);

typedef struct Model Model;   /* defined by the model file; the layer allocates model_size() bytes, zeroed */

size_t model_size(void);

/* exitInitializationMode: check the parameters p[N_PARAMETERS] (the layer has already checked
 * the declared [min, max]) and put the model in its start state. 0 ok; -1: an error naming the
 * culprit was logged, the instance refuses to step. Called again after fmi2Reset. */
int model_setup(Model *m, const double *p, const Log *log);

/* exitInitializationMode, after model_setup, with the inputs set in initialisation mode (all
 * finite; when not, the layer skips this and the model starts at its first step): outputs
 * consistent with them (the Python runtime's ``initialize``). */
void model_initialize(Model *m, const double *u, const Log *log);

/* Co-simulation: advance h seconds (0 < h <= MAX_STEP), inputs u[N_INPUTS] held (in range). Returns 0;
 * -1 = refused with an error logged, the state unchanged. */
int model_do_step(Model *m, double h, const double *u, const Log *log);

/* The outputs after model_setup / model_initialize / model_do_step (co-simulation). */
void model_outputs(const Model *m, double *y, int *yi);

/* Model exchange (a model with N_STATES > 0; layer_config.c stands in for a model without). The
 * continuous state x[N_STATES]; the discrete state (mode, flags) changes only in model_me_event_update. */
void model_me_get_states(const Model *m, double *x);
void model_me_set_states(Model *m, const double *x);
/* nominal magnitudes of the states (1.0 where nothing better is known) */
void model_me_nominals(const Model *m, double *nominal);
/* dx/dt at the current continuous and discrete state and inputs u */
void model_me_derivatives(const Model *m, const double *u, double *dx);
/* N_EVENT_INDICATORS values: a sign change of one is an event (mode switch, hold, validity) */
void model_me_event_indicators(const Model *m, const double *u, double *z);
/* Event mode (after initialisation, at a state event, or when the host asks): update the discrete
 * state from the current continuous state, inputs and time t (s). Returns 1 if it changed the
 * continuous state x, else 0. */
int model_me_event_update(Model *m, double t, const double *u, const Log *log);
/* the outputs at the current continuous and discrete state and inputs u (model exchange) */
void model_me_outputs(const Model *m, const double *u, double *y, int *yi);

#endif
