/* What the hand-written FMI 2.0 Co-Simulation test FMUs without Boolean or String
 * variables, FMU state, directional derivatives, input or output derivatives, an
 * asynchronous step or Model Exchange share (tests/data/spring_damper,
 * tests/data/work_bench): the version functions, debug logging (accepted, nothing to log),
 * and the functions they do not offer, each returning fmi2Error (fmpy loads every function
 * by name). Independent of pendulum-cosim's code; include after fmi2Functions.h. */
#ifndef FMI2_CS_MINIMAL_H
#define FMI2_CS_MINIMAL_H

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) { return fmi2OK; }

#define UNOFFERED return fmi2Error
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) { UNOFFERED; }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) { UNOFFERED; }
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) { UNOFFERED; }
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) { UNOFFERED; }
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { UNOFFERED; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { UNOFFERED; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { UNOFFERED; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) { UNOFFERED; }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) { UNOFFERED; }
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) { UNOFFERED; }
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu, const fmi2ValueReference k[], size_t nk, const fmi2Real dk[], fmi2Real du[]) { UNOFFERED; }
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[], const fmi2Real v[]) { UNOFFERED; }
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[], fmi2Real v[]) { UNOFFERED; }
fmi2Status fmi2CancelStep(fmi2Component c) { UNOFFERED; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) { UNOFFERED; }
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) { UNOFFERED; }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) { UNOFFERED; }
fmi2Status fmi2EnterEventMode(fmi2Component c) { UNOFFERED; }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *e) { UNOFFERED; }
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { UNOFFERED; }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean a, fmi2Boolean *b, fmi2Boolean *d) { UNOFFERED; }
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) { UNOFFERED; }
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t n) { UNOFFERED; }
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real d[], size_t n) { UNOFFERED; }
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real e[], size_t n) { UNOFFERED; }
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t n) { UNOFFERED; }
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t n) { UNOFFERED; }

#endif
