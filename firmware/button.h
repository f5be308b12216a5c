/* Capture-button logic: debounce a raw input line from timestamped edges and
 * tell short, long and double presses apart. Portable C11, no OS calls: the
 * caller feeds edges with their timestamps (µs, monotonic) and calls
 * vf_button_update() when the deadline from vf_button_next_deadline() has
 * passed. Levels are logical: 1 = pressed (the binding handles active-low). */
#ifndef VENEER_FIRMWARE_BUTTON_H
#define VENEER_FIRMWARE_BUTTON_H

#include <stdbool.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct {
  uint32_t debounce_us;   /* a level must hold this long to count; default 20 ms */
  uint32_t long_press_us; /* held at least this long = long press; default 800 ms */
  uint32_t double_gap_us; /* second press within this time after the first release
                             = double press; 0 = no double presses (short press is
                             reported on release); default 350 ms */
} vf_button_config;

typedef enum {
  VF_PRESS_NONE = 0,
  VF_PRESS_SHORT,
  VF_PRESS_LONG,
  VF_PRESS_DOUBLE
} vf_press;

typedef struct {
  vf_press press;
  uint64_t at_us; /* when the gesture was recognised */
} vf_button_event;

#define VF_BUTTON_QUEUE 8

typedef struct {
  vf_button_config cfg;
  int raw_level;         /* last level seen on the line */
  uint64_t raw_since_us; /* time of the last raw edge */
  int stable_level;      /* debounced level */
  uint64_t now_us;       /* latest time processed */
  int gesture;           /* internal gesture state */
  uint64_t mark_us;      /* press start or first release, depending on state */
  vf_button_event queue[VF_BUTTON_QUEUE];
  unsigned head, count;
  unsigned dropped;      /* events lost because the queue was full */
} vf_button;

/* Defaults: 20 ms debounce, 800 ms long press, 350 ms double-press gap. */
vf_button_config vf_button_default_config(void);

/* Starts with the line at `level` (taken as stable) at time `now_us`. */
void vf_button_init(vf_button* b, const vf_button_config* cfg, int level, uint64_t now_us);

/* A raw edge (or level sample) at time t_us. Non-monotonic times are clamped. */
void vf_button_edge(vf_button* b, int level, uint64_t t_us);

/* Advances time: commits levels that have been stable for the debounce time
 * and fires gesture timeouts (long press, end of the double-press window). */
void vf_button_update(vf_button* b, uint64_t now_us);

/* The next time something may happen without a new edge; false = none. */
bool vf_button_next_deadline(const vf_button* b, uint64_t* deadline_us);

/* Pops the oldest recognised gesture; false when there is none. */
bool vf_button_pop(vf_button* b, vf_button_event* out);

/* The debounced level (1 = pressed). */
int vf_button_level(const vf_button* b);

const char* vf_press_name(vf_press p);

#ifdef __cplusplus
}
#endif

#endif
