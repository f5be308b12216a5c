/* Status-LED patterns: the LED's level as a function of the state and the time
 * since the state was entered. Portable C11, no OS calls; the binding calls
 * vf_led_level() on a timer tick (vf_led_next_change() says when). */
#ifndef VENEER_FIRMWARE_LED_H
#define VENEER_FIRMWARE_LED_H

#include <stdbool.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum {
  VF_LED_IDLE = 0,   /* steady on: ready to capture */
  VF_LED_CAPTURING,  /* even blink, 2 Hz */
  VF_LED_DONE,       /* three quick flashes, then steady on like idle */
  VF_LED_ERROR,      /* double flash every second, repeating */
  VF_LED_NO_CAMERA,  /* slow blink: 1 s on, 1 s off */
  VF_LED_OFF,        /* dark (daemon stopped) */
  VF_LED_STATE_COUNT
} vf_led_state;

/* One step of a pattern: the level for `duration_ms`. */
typedef struct {
  uint8_t level;
  uint16_t duration_ms;
} vf_led_step;

#define VF_LED_MAX_STEPS 8

typedef struct {
  vf_led_step steps[VF_LED_MAX_STEPS];
  uint8_t count;  /* steps used */
  bool repeat;    /* false: the last step's level holds forever */
} vf_led_pattern;

const vf_led_pattern* vf_led_pattern_of(vf_led_state s);

/* LED level (1 = lit) at `now_us` for a state entered at `since_us`. */
int vf_led_level(vf_led_state s, uint64_t since_us, uint64_t now_us);

/* The first time after `now_us` at which the level may change; false when the
 * level holds forever (a steady pattern). */
bool vf_led_next_change(vf_led_state s, uint64_t since_us, uint64_t now_us, uint64_t* at_us);

const char* vf_led_state_name(vf_led_state s);

#ifdef __cplusplus
}
#endif

#endif
