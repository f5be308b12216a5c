#pragma once
// For the viewer's tests and bench: wait, processing Qt events, until a
// condition holds or `ms` milliseconds pass.
#include <QElapsedTimer>
#include <QTest>

template <class F>
bool wait_for(F cond, int ms) {
  QElapsedTimer t;
  t.start();
  while (!cond()) {
    if (t.elapsed() > ms) return false;
    QTest::qWait(10);
  }
  return true;
}
