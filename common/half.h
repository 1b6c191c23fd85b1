/* half: IEEE 754 binary16 conversion (round to nearest even; inf/NaN preserved). */
#ifndef LC_HALF_H
#define LC_HALF_H
#include <stdint.h>

uint16_t lc_half_from_float(float f);
float lc_half_to_float(uint16_t h);

#endif
