/* Model data of a pythonfmu TAPMP FMU (python_model.c): the model itself lives in a Python
 * object (the adapter's TapmpSlave subclass, fmu_common/slave.py). The instance keeps the
 * model's hidden state as the JSON text of the adapter's hidden_state(), one character
 * code per double (zero-padded), so that FMU states copy, check and serialize it exactly
 * as they do a native model's numbers. The build (orchestrator/builder/build.py) adds
 * MODEL_N_OUT and MODEL_OUT_FIRST from the variable table. */
#ifndef TAPMP_PYTHON_MODEL_H
#define TAPMP_PYTHON_MODEL_H

#define MODEL_OWN_RESOURCES 1
#define MODEL_N_HIDDEN 512  /* characters of hidden-state JSON: the controller's needs about 250 */

typedef struct {
    unsigned long stamp;            /* which state of the live Python model this describes (0: none) */
    double hidden[MODEL_N_HIDDEN];  /* the hidden state's JSON, valid when captured */
} ModelData;

/* The fmuGUID of the FMU's modelDescription.xml, read from resources/guid.txt at instantiation. */
static char tapmp_python_token[128];

#endif
