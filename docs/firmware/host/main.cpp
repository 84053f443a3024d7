// Host build of the reference firmware: Serial = stdin/stdout, runs for 3 s.
#include "Arduino.h"
#include "../mill_board.ino"
int main() {
  setup();
  unsigned long t0 = millis();
  while (millis() - t0 < 3000) loop();
  return 0;
}
