#include "led.h"

static const vf_led_pattern k_patterns[VF_LED_STATE_COUNT] = {
    /* idle */ {{{1, 1000}}, 1, false},
    /* capturing */ {{{1, 250}, {0, 250}}, 2, true},
    /* done */ {{{1, 100}, {0, 100}, {1, 100}, {0, 100}, {1, 100}, {0, 100}, {1, 1000}}, 7, false},
    /* error */ {{{1, 100}, {0, 100}, {1, 100}, {0, 700}}, 4, true},
    /* no camera */ {{{1, 1000}, {0, 1000}}, 2, true},
    /* off */ {{{0, 1000}}, 1, false},
};

const vf_led_pattern* vf_led_pattern_of(vf_led_state s) {
  if ((int)s < 0 || s >= VF_LED_STATE_COUNT) s = VF_LED_ERROR;
  return &k_patterns[s];
}

static uint64_t pattern_length_us(const vf_led_pattern* p) {
  uint64_t total = 0;
  for (unsigned i = 0; i < p->count; ++i) total += (uint64_t)p->steps[i].duration_ms * 1000u;
  return total;
}

/* Finds the step active at `offset` (µs into the pattern) and where it ends. */
static unsigned locate(const vf_led_pattern* p, uint64_t offset, uint64_t* step_end, bool* forever) {
  uint64_t length = pattern_length_us(p);
  *forever = false;
  uint64_t cycle_start = 0;
  if (p->repeat) {
    cycle_start = offset - offset % length;
    offset %= length;
  } else if (offset >= length) {
    *forever = true;
    *step_end = 0;
    return p->count - 1u;
  }
  uint64_t end = 0;
  for (unsigned i = 0; i < p->count; ++i) {
    end += (uint64_t)p->steps[i].duration_ms * 1000u;
    if (offset < end) {
      *step_end = cycle_start + end;
      /* The last step of a one-shot pattern holds forever. */
      if (!p->repeat && i + 1u == p->count) *forever = true;
      return i;
    }
  }
  *step_end = cycle_start + end;
  return p->count - 1u;
}

int vf_led_level(vf_led_state s, uint64_t since_us, uint64_t now_us) {
  const vf_led_pattern* p = vf_led_pattern_of(s);
  uint64_t offset = now_us > since_us ? now_us - since_us : 0;
  uint64_t end;
  bool forever;
  unsigned i = locate(p, offset, &end, &forever);
  return p->steps[i].level ? 1 : 0;
}

bool vf_led_next_change(vf_led_state s, uint64_t since_us, uint64_t now_us, uint64_t* at_us) {
  const vf_led_pattern* p = vf_led_pattern_of(s);
  uint64_t offset = now_us > since_us ? now_us - since_us : 0;
  uint64_t end;
  bool forever;
  unsigned i = locate(p, offset, &end, &forever);
  int level = p->steps[i].level;
  /* Skip following steps with the same level so a tick lands on a real change. */
  for (unsigned guard = 0; !forever && guard < 2u * VF_LED_MAX_STEPS; ++guard) {
    unsigned next_i = locate(p, end, &end, &forever);
    if (p->steps[next_i].level != level) {
      /* `end` now is the end of next_i; the change happened at its start. */
      uint64_t start = end - (uint64_t)p->steps[next_i].duration_ms * 1000u;
      if (at_us) *at_us = since_us + start;
      return true;
    }
  }
  return false;
}

const char* vf_led_state_name(vf_led_state s) {
  switch (s) {
    case VF_LED_IDLE: return "idle";
    case VF_LED_CAPTURING: return "capturing";
    case VF_LED_DONE: return "done";
    case VF_LED_ERROR: return "error";
    case VF_LED_NO_CAMERA: return "no camera";
    case VF_LED_OFF: return "off";
    default: return "unknown";
  }
}
