/* What fmi3UpdateDiscreteStates reports for a native TAPMP FMU, in Co-Simulation's Event Mode and in
 * Model Exchange alike: one update settles the event (no discrete state depends on what the update
 * changes), no continuous state or nominal changes, and the next time event if the model has one. */
#ifndef TAPMP_FMI3_EVENTS_H
#define TAPMP_FMI3_EVENTS_H

#include "fmi3Functions.h"

static inline void tapmp_fmi3_report_update(int defined, double next, fmi3Boolean *discreteStatesNeedUpdate,
                                            fmi3Boolean *terminateSimulation,
                                            fmi3Boolean *nominalsOfContinuousStatesChanged,
                                            fmi3Boolean *valuesOfContinuousStatesChanged,
                                            fmi3Boolean *nextEventTimeDefined, fmi3Float64 *nextEventTime)
{
    if (discreteStatesNeedUpdate) *discreteStatesNeedUpdate = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (nominalsOfContinuousStatesChanged) *nominalsOfContinuousStatesChanged = fmi3False;
    if (valuesOfContinuousStatesChanged) *valuesOfContinuousStatesChanged = fmi3False;
    if (nextEventTimeDefined) *nextEventTimeDefined = defined ? fmi3True : fmi3False;
    if (nextEventTime) *nextEventTime = next;
}

#endif
