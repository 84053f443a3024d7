// drumtwin mill board -- reference firmware (Arduino Uno/Nano class board).
//
// Implements docs/mill-protocol.md v1: frames "$seq,CMD[,args]*CRC16\n", ACK/NAK with the
// same seq, resend detection (last seq+payload of SET/RUN/STP -> cached reply, never
// applied twice; STA/HB are always answered with a fresh status),
// absolute setpoints, and the watchdog (no HB/SET/RUN/STP frame for WATCHDOG_MS while
// running -> stop, fault WDOG; STA does not feed it). The logic mirrors control/device.py, which the emulator runs and the
// tests exercise; keep the two in step.
//
// Hardware assumed: a DC gear motor on a PWM driver (PWM_PIN, DIR not needed: one
// direction), a Hall/optical tachometer on the drum shaft giving PULSES_PER_REV pulses
// per revolution on TACH_PIN (interrupt capable), an optional drive-fault input
// (FAULT_PIN, active low). Speed loop: accel-limited ramp of the target + PI on the
// measured rpm. Tune KP/KI for your drive.

#include <Arduino.h>
#include <string.h>
#include <stdlib.h>
#include <ctype.h>
#include <stdio.h>

// ---- configuration --------------------------------------------------------------------
const unsigned long BAUD = 115200;
const uint8_t PWM_PIN = 9;
const uint8_t TACH_PIN = 2;
const uint8_t FAULT_PIN = 7;
const float PULSES_PER_REV = 4.0f;
const float MAX_RPM = 60.0f;
const float ACCEL_RPM_PER_S = 10.0f;
const unsigned long WATCHDOG_MS = 1000;  // 0 disables (commissioning only)
const float KP = 4.0f, KI = 8.0f;        // PWM counts per rpm, per rpm*s
const unsigned long LOOP_MS = 10;
const uint8_t MAX_LINE = 64;

// ---- state ----------------------------------------------------------------------------
float setpointRpm = 0.0f;  // commanded by SET
float rampRpm = 0.0f;      // accel-limited target fed to the PI loop
float actualRpm = 0.0f;
bool running = false;
const char *fault = "OK";  // "OK" | "WDOG" | "DRIVE"
float integ = 0.0f;

volatile unsigned long tachPulses = 0;
unsigned long lastValidMs = 0, lastLoopMs = 0, lastTachMs = 0, lastTachCount = 0;

char line[MAX_LINE + 1];
uint8_t lineLen = 0;
bool inFrame = false, overflow = false;

long lastSeq = -1;
char lastPayload[MAX_LINE + 1] = "";
char lastReply[MAX_LINE + 1] = "";

void onTach() { tachPulses++; }

// CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF ("123456789" -> 0x29B1)
uint16_t crc16(const char *data, size_t n) {
  uint16_t crc = 0xFFFF;
  for (size_t i = 0; i < n; i++) {
    crc ^= (uint16_t)(uint8_t)data[i] << 8;
    for (uint8_t b = 0; b < 8; b++) crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
  }
  return crc;
}

// Build "$<body>*CRC\n" into out.
void frame(char *out, const char *body) {
  char crc[5];
  snprintf(crc, sizeof crc, "%04X", crc16(body, strlen(body)));
  snprintf(out, MAX_LINE + 1, "$%s*%s\n", body, crc);
}

void fmtRpm(char *out, float v) {  // 2 decimals without printf float support
  long c = (long)(v * 100.0f + 0.5f);
  snprintf(out, 24, "%ld.%02ld", c / 100, c % 100);
}

void statusBody(char *body, long seq) {
  char sp[24], act[24];
  fmtRpm(sp, setpointRpm);
  fmtRpm(act, actualRpm);
  snprintf(body, MAX_LINE, "%ld,ACK,%s,%s,%d,%s", seq, sp, act, running ? 1 : 0, fault);
}

// A setpoint argument: digits with at most one '.', <= 3 decimals, no sign/exponent.
bool parseRpm(const char *s, float *out) {
  uint8_t dots = 0, dec = 0, digits = 0;
  if (*s == '+') s++;
  for (const char *p = s; *p; p++) {
    if (*p == '.') { if (++dots > 1) return false; continue; }
    if (*p < '0' || *p > '9') return false;
    if (dots) { if (++dec > 3) return false; } else if (++digits > 5) return false;
  }
  if (!digits) return false;
  *out = (float)atof(s);
  return true;
}

void execute(long seq, char *payload, char *reply) {
  char body[MAX_LINE];
  char work[MAX_LINE + 1];
  strncpy(work, payload, MAX_LINE);
  work[MAX_LINE] = 0;
  char *cmd = strtok(work, ",");
  char *arg = strtok(NULL, ",");
  char *extra = strtok(NULL, ",");
  const char *nak = NULL;
  if (!cmd) nak = "CMD";
  else if (!strcmp(cmd, "SET")) {
    float v;
    if (!arg || extra || !parseRpm(arg, &v)) nak = "ARG";
    else if (v > MAX_RPM) nak = "RANGE";
    else setpointRpm = v;
  } else if (!strcmp(cmd, "RUN") || !strcmp(cmd, "STP") || !strcmp(cmd, "STA") || !strcmp(cmd, "HB")) {
    if (arg) nak = "ARG";
    else if (!strcmp(cmd, "RUN")) {
      if (!strcmp(fault, "DRIVE")) nak = "FAULT";
      else { fault = "OK"; running = true; }
    } else if (!strcmp(cmd, "STP")) running = false;
    else { statusBody(body, seq); frame(reply, body); return; }
  } else nak = "CMD";
  if (nak) snprintf(body, sizeof body, "%ld,NAK,%s", seq, nak);
  else snprintf(body, sizeof body, "%ld,ACK", seq);
  frame(reply, body);
}

// True when the payload's command is `cmd` ("SET" matches "SET,12.00", not "SETX").
bool isCommand(const char *payload, const char *cmd) {
  size_t n = strlen(cmd);
  return !strncmp(payload, cmd, n) && (payload[n] == ',' || payload[n] == 0);
}

// The controlling host's commands feed the watchdog: HB, SET, RUN, STP (not STA).
bool feedsWatchdog(const char *payload) {
  return isCommand(payload, "HB") || isCommand(payload, "SET") || isCommand(payload, "RUN") ||
         isCommand(payload, "STP");
}

// One complete line "$...": check syntax and CRC, dedup, execute, answer.
void handleLine(const char *l, uint8_t n) {
  const char *star = (const char *)memchr(l, '*', n);
  if (l[0] != '$' || !star || (uint8_t)(l + n - star) != 5) return;  // syntax: no answer
  size_t bodyLen = star - (l + 1);
  char body[MAX_LINE + 1];
  memcpy(body, l + 1, bodyLen);
  body[bodyLen] = 0;
  char *comma = strchr(body, ',');
  if (!comma || comma == body || comma - body > 5) return;
  for (char *p = body; p < comma; p++) if (*p < '0' || *p > '9') return;
  long seq = atol(body);
  if (seq > 65535) return;
  char crcTxt[5];
  memcpy(crcTxt, star + 1, 4);
  crcTxt[4] = 0;
  for (uint8_t i = 0; i < 4; i++) if (!isxdigit(crcTxt[i]) || islower(crcTxt[i])) return;
  char reply[MAX_LINE + 1];
  if ((uint16_t)strtoul(crcTxt, NULL, 16) != crc16(body, bodyLen)) {
    char nb[40];
    snprintf(nb, sizeof nb, "%ld,NAK,CRC", seq);
    frame(reply, nb);
    Serial.write(reply);
    return;
  }
  char *payload = comma + 1;
  // Only the controlling host feeds the watchdog (HB, SET, RUN, STP, resends included);
  // STA does not, so a status poller cannot keep the motor running after the
  // controlling host died.
  if (feedsWatchdog(payload)) lastValidMs = millis();
  if (isCommand(payload, "STA") || isCommand(payload, "HB")) {  // read-only: always a fresh
    execute(seq, payload, reply);                                // status, never cached
    Serial.write(reply);
    return;
  }
  if (seq == lastSeq && !strcmp(payload, lastPayload)) {  // resend: same answer, no re-apply,
    if (isCommand(payload, "STP")) running = false;      // but a stop always stops (never refused)
    Serial.write(lastReply);
    return;
  }
  execute(seq, payload, reply);
  lastSeq = seq;
  strncpy(lastPayload, payload, MAX_LINE);
  strncpy(lastReply, reply, MAX_LINE);
  Serial.write(reply);
}

void readSerial() {
  while (Serial.available()) {
    char c = (char)Serial.read();
    if (c == '$') { inFrame = true; overflow = false; lineLen = 0; line[lineLen++] = c; }
    else if (c == '\n') { if (inFrame && !overflow) handleLine(line, lineLen); inFrame = false; lineLen = 0; }
    else if (c == '\r' || !inFrame || overflow) continue;
    else if (c < 0x20 || c > 0x7E) { inFrame = false; lineLen = 0; }  // binary: drop the frame
    else if (lineLen + 1 >= MAX_LINE) overflow = true;                 // too long: drop up to '\n'/'$'
    else line[lineLen++] = c;
  }
}

void speedLoop(float dt) {
  // measured rpm from the tachometer, every 100 ms
  unsigned long now = millis();
  if (now - lastTachMs >= 100) {
    noInterrupts();
    unsigned long p = tachPulses;
    interrupts();
    actualRpm = (p - lastTachCount) / PULSES_PER_REV * 60000.0f / (now - lastTachMs);
    lastTachCount = p;
    lastTachMs = now;
  }
  if (digitalRead(FAULT_PIN) == LOW) { fault = "DRIVE"; running = false; }
  if (WATCHDOG_MS && running && now - lastValidMs > WATCHDOG_MS) { running = false; fault = "WDOG"; }
  float target = running ? setpointRpm : 0.0f;
  float maxStep = ACCEL_RPM_PER_S * dt;
  rampRpm += constrain(target - rampRpm, -maxStep, maxStep);
  if (rampRpm <= 0.0f && !running) { integ = 0; analogWrite(PWM_PIN, 0); return; }
  float err = rampRpm - actualRpm;
  integ = constrain(integ + KI * err * dt, 0.0f, 255.0f);
  analogWrite(PWM_PIN, (int)constrain(KP * err + integ, 0.0f, 255.0f));
}

void setup() {
  pinMode(PWM_PIN, OUTPUT);
  analogWrite(PWM_PIN, 0);
  pinMode(FAULT_PIN, INPUT_PULLUP);
  pinMode(TACH_PIN, INPUT_PULLUP);
  attachInterrupt(digitalPinToInterrupt(TACH_PIN), onTach, RISING);
  Serial.begin(BAUD);
  lastValidMs = lastLoopMs = lastTachMs = millis();
}

void loop() {
  readSerial();
  unsigned long now = millis();
  if (now - lastLoopMs >= LOOP_MS) {
    speedLoop((now - lastLoopMs) / 1000.0f);
    lastLoopMs = now;
  }
}
