#include "button.h"

enum {
  G_IDLE = 0,     /* released, nothing pending */
  G_PRESSED,      /* first press held, long-press deadline running */
  G_HELD_LONG,    /* long press reported, waiting for release */
  G_WAIT_SECOND,  /* released after a short press, double-press window open */
  G_HELD_DOUBLE   /* double press reported, waiting for release */
};

vf_button_config vf_button_default_config(void) {
  vf_button_config c;
  c.debounce_us = 20000;
  c.long_press_us = 800000;
  c.double_gap_us = 350000;
  return c;
}

void vf_button_init(vf_button* b, const vf_button_config* cfg, int level, uint64_t now_us) {
  b->cfg = cfg ? *cfg : vf_button_default_config();
  b->raw_level = level ? 1 : 0;
  b->raw_since_us = now_us;
  b->stable_level = b->raw_level;
  b->now_us = now_us;
  /* A button already held at start is ignored until it is released. */
  b->gesture = b->stable_level ? G_HELD_LONG : G_IDLE;
  b->mark_us = now_us;
  b->head = 0;
  b->count = 0;
  b->dropped = 0;
}

static void emit(vf_button* b, vf_press p, uint64_t at) {
  if (b->count == VF_BUTTON_QUEUE) {
    b->dropped++;
    return;
  }
  unsigned tail = (b->head + b->count) % VF_BUTTON_QUEUE;
  b->queue[tail].press = p;
  b->queue[tail].at_us = at;
  b->count++;
}

/* Gesture deadline in the current state, if any. */
static bool gesture_deadline(const vf_button* b, uint64_t* t) {
  switch (b->gesture) {
    case G_PRESSED:
      *t = b->mark_us + b->cfg.long_press_us;
      return true;
    case G_WAIT_SECOND:
      *t = b->mark_us + b->cfg.double_gap_us;
      return true;
    default:
      return false;
  }
}

static void fire_deadline(vf_button* b, uint64_t t) {
  if (b->gesture == G_PRESSED) {
    emit(b, VF_PRESS_LONG, t);
    b->gesture = G_HELD_LONG;
  } else if (b->gesture == G_WAIT_SECOND) {
    emit(b, VF_PRESS_SHORT, t);
    b->gesture = G_IDLE;
  }
}

/* A debounced transition to `level` that began at `t` (the edge time). */
static void commit(vf_button* b, int level, uint64_t t, uint64_t confirmed_at) {
  b->stable_level = level;
  if (level) {
    if (b->gesture == G_IDLE) {
      b->gesture = G_PRESSED;
      b->mark_us = t;
    } else if (b->gesture == G_WAIT_SECOND) {
      emit(b, VF_PRESS_DOUBLE, confirmed_at);
      b->gesture = G_HELD_DOUBLE;
    }
  } else {
    if (b->gesture == G_PRESSED) {
      if (b->cfg.double_gap_us == 0) {
        emit(b, VF_PRESS_SHORT, confirmed_at);
        b->gesture = G_IDLE;
      } else {
        b->gesture = G_WAIT_SECOND;
        b->mark_us = t;
      }
    } else if (b->gesture == G_HELD_LONG || b->gesture == G_HELD_DOUBLE) {
      b->gesture = G_IDLE;
    }
  }
}

void vf_button_update(vf_button* b, uint64_t now_us) {
  if (now_us < b->now_us) now_us = b->now_us;
  b->now_us = now_us;
  for (;;) {
    bool pending = b->raw_level != b->stable_level;
    uint64_t commit_at = b->raw_since_us + b->cfg.debounce_us;
    uint64_t dl = 0;
    bool has_dl = gesture_deadline(b, &dl);
    /* A gesture deadline after an unconfirmed edge waits until that edge is
     * either confirmed or bounced away: a release at 790 ms must not turn
     * into a long press at 800 ms just because debounce is still running. */
    if (has_dl && (!pending || dl < b->raw_since_us) && dl <= now_us) {
      fire_deadline(b, dl);
      continue;
    }
    if (pending && commit_at <= now_us) {
      commit(b, b->raw_level, b->raw_since_us, commit_at);
      continue;
    }
    break;
  }
}

void vf_button_edge(vf_button* b, int level, uint64_t t_us) {
  level = level ? 1 : 0;
  if (t_us < b->now_us) t_us = b->now_us;
  vf_button_update(b, t_us);
  if (level == b->raw_level) return;
  b->raw_level = level;
  b->raw_since_us = t_us;
}

bool vf_button_next_deadline(const vf_button* b, uint64_t* deadline_us) {
  bool any = false;
  uint64_t best = 0;
  bool pending = b->raw_level != b->stable_level;
  if (pending) {
    best = b->raw_since_us + b->cfg.debounce_us;
    any = true;
  }
  uint64_t dl = 0;
  if (gesture_deadline(b, &dl) && (!pending || dl < b->raw_since_us)) {
    if (!any || dl < best) best = dl;
    any = true;
  }
  if (any && deadline_us) *deadline_us = best;
  return any;
}

bool vf_button_pop(vf_button* b, vf_button_event* out) {
  if (b->count == 0) return false;
  if (out) *out = b->queue[b->head];
  b->head = (b->head + 1) % VF_BUTTON_QUEUE;
  b->count--;
  return true;
}

int vf_button_level(const vf_button* b) { return b->stable_level; }

const char* vf_press_name(vf_press p) {
  switch (p) {
    case VF_PRESS_SHORT: return "short";
    case VF_PRESS_LONG: return "long";
    case VF_PRESS_DOUBLE: return "double";
    default: return "none";
  }
}
