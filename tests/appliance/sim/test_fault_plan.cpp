// The fault plan (veneerd/sim/fault_plan.hpp): its SPEC, its draws (random
// from a seed, or on a schedule), and the twins taking its faults.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <thread>

#include "veneer/util/utc_time.hpp"
#include "veneerd/sim/fault_plan.hpp"
#include "veneerd/sim/simulated_rig.hpp"

using veneerd::Fault;
using veneerd::FaultPlan;

TEST(FaultPlan, ParsesTheSpecAndSaysItBack) {
  auto p = FaultPlan::parse("bridge.503=0.02,camera.gone=0.01,store.eio=0.01,camera.gone@3,store.slow_ms=120,seed=7");
  ASSERT_TRUE(p) << p.message();
  EXPECT_TRUE(p->has(Fault::bridge_503));
  EXPECT_TRUE(p->has(Fault::camera_gone));
  EXPECT_TRUE(p->has(Fault::store_eio));
  EXPECT_FALSE(p->has(Fault::bridge_429));
  EXPECT_FALSE(p->empty());
  EXPECT_EQ(p->seed(), 7u);
  EXPECT_EQ(p->sizes().store_slow_ms, 120);
  EXPECT_EQ(p->sizes().camera_gone_ms, 800) << "the default";
  EXPECT_EQ(p->spec(), "bridge.503=0.02,camera.gone=0.01,camera.gone@3,store.eio=0.01,store.slow_ms=120,seed=7");
  auto again = FaultPlan::parse(p->spec());
  ASSERT_TRUE(again);
  EXPECT_EQ(again->spec(), p->spec());
  // The same plan as JSON.
  auto j = FaultPlan::parse(R"({"bridge.503": 0.02, "camera.gone": 0.01, "store.eio": 0.01, "camera.gone@": [3],
                                "store.slow_ms": 120, "seed": 7})");
  ASSERT_TRUE(j) << j.message();
  EXPECT_EQ(j->spec(), p->spec());
  auto none = FaultPlan::parse("");
  ASSERT_TRUE(none);
  EXPECT_TRUE(none->empty());
}

TEST(FaultPlan, RefusesABadSpecNamingTheItem) {
  struct Case {
    const char* spec;
    const char* names;
  };
  for (const Case& c : {Case{"bridge.5O3=0.1", "'bridge.5O3=0.1': no fault named 'bridge.5O3'"},
                        Case{"bridge.503=1.5", "'bridge.503=1.5': a rate is a probability 0..1"},
                        Case{"bridge.503=x", "a rate is a probability"},
                        Case{"camera.gone@0", "'camera.gone@0': a schedule takes"},
                        Case{"seed=-3", "'seed=-3': the seed is a whole number"},
                        Case{"store.slow_ms=0", "'store.slow_ms=0': must be a whole number 1..60000"},
                        Case{"bridge.503", "expected NAME=VALUE or NAME@N"},
                        Case{"{\"bridge.503\": \"often\"}", "'bridge.503': the value must be a number"},
                        Case{"{\"bridge.503\": 0.1", "not a JSON object"}}) {
    auto p = FaultPlan::parse(c.spec);
    ASSERT_FALSE(p) << c.spec;
    EXPECT_NE(p.message().find(c.names), std::string::npos) << c.spec << " -> " << p.message();
    EXPECT_EQ(p.message().rfind("--faults: ", 0), 0u) << p.message();
  }
}

TEST(FaultPlan, SchedulesHitTheirOpportunityAndRatesHoldFromTheSeed) {
  auto p = FaultPlan::parse("camera.gone@3,camera.gone@5,bridge.503=0.1,seed=42");
  ASSERT_TRUE(p);
  std::vector<int> hits;
  for (int n = 1; n <= 8; ++n)
    if (p->draw(Fault::camera_gone)) hits.push_back(n);
  EXPECT_EQ(hits, (std::vector<int>{3, 5}));
  EXPECT_EQ(p->count(Fault::camera_gone).opportunities, 8u);
  EXPECT_EQ(p->count(Fault::camera_gone).taken, 2u);
  // 10000 draws at 0.1: 1000 expected, sd 30.
  std::vector<bool> first;
  int taken = 0;
  for (int n = 0; n < 10000; ++n) {
    const bool t = p->draw(Fault::bridge_503);
    taken += t;
    if (n < 200) first.push_back(t);
  }
  EXPECT_NEAR(taken, 1000, 150);
  // The same seed draws the same faults, whatever other faults drew between.
  auto q = FaultPlan::parse("camera.gone@3,camera.gone@5,bridge.503=0.1,seed=42");
  ASSERT_TRUE(q);
  std::vector<bool> again;
  for (int n = 0; n < 200; ++n) {
    q->draw(Fault::camera_gone);
    again.push_back(q->draw(Fault::bridge_503));
  }
  EXPECT_EQ(again, first);
  EXPECT_FALSE(p->draw(Fault::store_eio)) << "a fault the plan does not name is never taken";
}

TEST(FaultPlan, TheTwinsTakeTheirFaults) {
  veneerd::SimulatedRigOptions o;
  o.size = {64, 48};
  o.noise_sigma = 0;
  auto rig = veneerd::SimulatedRig::start(o);
  ASSERT_TRUE(rig) << rig.message();
  auto plan = FaultPlan::parse("bridge.503@1,bridge.drop@2,camera.gone@2,camera.gone_ms=300,clock.step@1,clock.step_s=7200");
  ASSERT_TRUE(plan);
  auto shared = std::make_shared<FaultPlan>(*plan);
  (*rig)->bridge().set_fault_plan(shared);
  auto camera = (*rig)->make_camera();
  ASSERT_TRUE(camera) << camera.message();
  (*camera)->set_fault_plan(shared);
  std::atomic<int> lost{0}, back{0};
  (*camera)->on_connection_change = [&](bool connected) { ++(connected ? back : lost); };

  // Shot 1: the clock steps (the lamps are read through a 503 and a dropped connection, retried).
  const std::time_t before = veneer::wall_now();
  auto first = (*camera)->capture();
  ASSERT_TRUE(first) << first.message();
  const long long stepped = static_cast<long long>(veneer::wall_now() - before);
  EXPECT_TRUE(std::abs(std::abs(stepped) - 7200) <= 2) << stepped;
  veneer::step_wall_clock(-stepped);  // back as it was, for the other tests
  EXPECT_GE((*rig)->bridge().counters().injected, 1u);
  EXPECT_GE((*rig)->bridge().counters().dropped, 1u);
  // Shot 2: the camera drops off USB and comes back 300 ms later.
  auto second = (*camera)->capture();
  ASSERT_FALSE(second);
  EXPECT_NE(second.message().find("not connected (unplugged)"), std::string::npos) << second.message();
  EXPECT_EQ(lost.load(), 1);
  for (int i = 0; i < 100 && back.load() == 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  EXPECT_EQ(back.load(), 1) << "plugged in again";
  EXPECT_TRUE((*camera)->connected());
  auto third = (*camera)->capture();
  EXPECT_TRUE(third) << third.message();
  EXPECT_EQ(shared->count(Fault::camera_gone).taken, 1u);
  EXPECT_EQ(shared->count(Fault::bridge_503).taken, 1u);
}
