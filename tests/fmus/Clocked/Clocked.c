/* Test FMU (FMI 3.0 co-simulation, written in C): a front-to-back fill strategy and a do-nothing offloading
 * controller whose decisions are clocked by the input clock `tick` (value reference 1). graincosim ticks it once
 * per decision; the FMU checks the importer's calling sequence and refuses a wrong one with fmi3Error:
 *
 *  - clocked inputs (`full`, `height`) can be set, and clocked outputs (`section`, `nudge`, `auger_on`, `tick_time`)
 *    read, only in Event Mode while `tick` is active;
 *  - doStep must start where the FMU's time stands (no gap, no overlap);
 *  - with the parameter period_s > 0, a tick must fall on a multiple of period_s (a periodic clock).
 *
 * At a tick (fmi3UpdateDiscreteStates with `tick` active): section = the first section 1..9 not full (0: all full);
 * tick_time = the FMU's time; nudge = 0; auger_on = time < auger_until_s; ticks counts the ticks (not clocked).
 * The model description (modelDescription.xml) declares the variables; tests/fmu_builds.py compiles this file with
 * stubs for the FMI functions it does not implement (they return fmi3Error).
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"

#define N 9
enum { VR_TIME, VR_TICK, VR_FULL, VR_HEIGHT, VR_SECTION, VR_NUDGE, VR_AUGER, VR_TICK_TIME, VR_TICKS, VR_PERIOD,
       VR_AUGER_UNTIL };
enum { INSTANTIATED, INITIALIZATION, EVENT, STEP, TERMINATED };

typedef struct {
    int mode;
    int event_mode_used;
    double time;
    fmi3Boolean tick;
    fmi3Boolean full[N];
    double height[N];
    int section, nudge, ticks;
    fmi3Boolean auger_on;
    double tick_time, period_s, auger_until_s;
} Model;

static int clocked_ok(const Model *m) { return m->mode == EVENT && m->tick; }

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    return fmi3OK;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    if (!eventModeUsed) return NULL;  /* a clocked FMU needs Event Mode */
    Model *m = calloc(1, sizeof(Model));
    m->mode = INSTANTIATED;
    m->event_mode_used = eventModeUsed;
    for (int k = 0; k < N; k++) m->height[k] = NAN;
    return m;
}

void fmi3FreeInstance(fmi3Instance instance) { free(instance); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    Model *m = instance;
    m->time = startTime;
    m->mode = INITIALIZATION;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    ((Model *)instance)->mode = EVENT;
    return fmi3OK;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    Model *m = instance;
    if (m->mode != STEP) return fmi3Error;
    m->mode = EVENT;
    return fmi3OK;
}

fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    Model *m = instance;
    if (m->mode != EVENT) return fmi3Error;
    m->mode = STEP;
    m->tick = fmi3False;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    ((Model *)instance)->mode = TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) { return fmi3Error; }

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[]) {
    Model *m = instance;
    if (m->mode != EVENT) return fmi3Error;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != VR_TICK) return fmi3Error;
        if (values[i] && m->period_s > 0.0) {
            double k = m->time / m->period_s;
            if (fabs(k - round(k)) > 1e-9) return fmi3Error;  /* off the period */
        }
        m->tick = values[i];
    }
    return fmi3OK;
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[]) {
    Model *m = instance;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != VR_TICK) return fmi3Error;
        values[i] = m->tick;
    }
    return fmi3OK;
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined, fmi3Float64 *nextEventTime) {
    Model *m = instance;
    if (m->mode != EVENT) return fmi3Error;
    if (m->tick) {
        m->section = 0;
        for (int k = 0; k < N; k++) {
            if (!m->full[k]) { m->section = k + 1; break; }
        }
        m->nudge = 0;
        m->auger_on = m->time < m->auger_until_s;
        m->tick_time = m->time;
        m->ticks += 1;
    }
    *discreteStatesNeedUpdate = fmi3False;
    *terminateSimulation = fmi3False;
    *nominalsOfContinuousStatesChanged = fmi3False;
    *valuesOfContinuousStatesChanged = fmi3False;
    *nextEventTimeDefined = fmi3False;
    *nextEventTime = 0.0;
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    Model *m = instance;
    if (m->mode != STEP || fabs(currentCommunicationPoint - m->time) > 1e-9) return fmi3Error;
    m->time = currentCommunicationPoint + communicationStepSize;
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = m->time;
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues) {
    Model *m = instance;
    size_t at = 0;
    for (size_t i = 0; i < nvr; i++) {
        switch (vr[i]) {
        case VR_TIME: values[at++] = m->time; break;
        case VR_TICK_TIME: if (!clocked_ok(m)) return fmi3Error; values[at++] = m->tick_time; break;
        case VR_HEIGHT: for (int k = 0; k < N; k++) values[at++] = m->height[k]; break;
        case VR_PERIOD: values[at++] = m->period_s; break;
        case VR_AUGER_UNTIL: values[at++] = m->auger_until_s; break;
        default: return fmi3Error;
        }
    }
    return at == nValues ? fmi3OK : fmi3Error;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues) {
    Model *m = instance;
    size_t at = 0;
    for (size_t i = 0; i < nvr; i++) {
        switch (vr[i]) {
        case VR_HEIGHT:
            if (!clocked_ok(m)) return fmi3Error;
            for (int k = 0; k < N; k++) m->height[k] = values[at++];
            break;
        case VR_PERIOD:
            if (m->mode != INSTANTIATED) return fmi3Error;
            m->period_s = values[at++];
            break;
        case VR_AUGER_UNTIL:
            if (m->mode != INSTANTIATED) return fmi3Error;
            m->auger_until_s = values[at++];
            break;
        default: return fmi3Error;
        }
    }
    return at == nValues ? fmi3OK : fmi3Error;
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Int32 values[],
                        size_t nValues) {
    Model *m = instance;
    size_t at = 0;
    for (size_t i = 0; i < nvr; i++) {
        switch (vr[i]) {
        case VR_SECTION: if (!clocked_ok(m)) return fmi3Error; values[at++] = m->section; break;
        case VR_NUDGE: if (!clocked_ok(m)) return fmi3Error; values[at++] = m->nudge; break;
        case VR_TICKS: values[at++] = m->ticks; break;
        default: return fmi3Error;
        }
    }
    return at == nValues ? fmi3OK : fmi3Error;
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Boolean values[],
                          size_t nValues) {
    Model *m = instance;
    size_t at = 0;
    for (size_t i = 0; i < nvr; i++) {
        switch (vr[i]) {
        case VR_AUGER: if (!clocked_ok(m)) return fmi3Error; values[at++] = m->auger_on; break;
        case VR_FULL: for (int k = 0; k < N; k++) values[at++] = m->full[k]; break;
        default: return fmi3Error;
        }
    }
    return at == nValues ? fmi3OK : fmi3Error;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Boolean values[], size_t nValues) {
    Model *m = instance;
    size_t at = 0;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != VR_FULL || !clocked_ok(m)) return fmi3Error;
        for (int k = 0; k < N; k++) m->full[k] = values[at++];
    }
    return at == nValues ? fmi3OK : fmi3Error;
}
