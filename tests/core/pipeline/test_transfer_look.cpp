// metrics.json's "look" block of a transfer (pipeline/transfer_look.cpp): the
// reference it was measured against, the figures equal to eval::look's on the
// files written, the floor.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>

#include <nlohmann/json.hpp>

#include "veneer/eval/look.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer::pipeline {
namespace {
namespace fs = std::filesystem;

io::ImageSet simulated(const std::string& scene, io::Role role, cv::Vec3d offset = {0, 0, 0}, double noise = 0) {
  sim::RenderOptions o;
  o.size = {128, 85};
  o.offset_m = offset;
  o.noise_sigma = noise;
  auto set = sim::simulate_set(scene, o, role);
  EXPECT_TRUE(set.ok()) << (set.ok() ? "" : set.message());
  return set.ok() ? *set : io::ImageSet{};
}

nlohmann::json look_of(const TransferResult& r) {
  const nlohmann::json j = nlohmann::json::parse(r.metrics_json);
  EXPECT_TRUE(j.contains("look")) << j.value("look_error", std::string());
  return j.contains("look") ? j["look"] : nlohmann::json::object();
}

// The look block's figures on the copy look, whose pictures stay within what
// the 16-bit files hold and whose `linear` transfer is its own floor (the
// shaded look is scored in core/ShadedLook.*).
TransferOptions method(match::Method m) {
  TransferOptions o;
  o.look = repaint::Look::copy;
  o.match.method = m;
  o.truth_normals = true;
  return o;
}

TEST(TransferLook, SimulatedPairIsScoredAgainstTheTruthLook) {
  // made as `veneer simulate` makes them (noise 0.005)
  const io::ImageSet dst = simulated("bull", io::Role::destination, {0, 0, 0}, 0.005);
  const io::ImageSet src = simulated("orange", io::Role::source, {0, 0, 0}, 0.005);
  auto r = transfer(dst, src, method(match::Method::coherent));
  ASSERT_TRUE(r.ok()) << r.message();
  const nlohmann::json look = look_of(*r);
  EXPECT_NE(look.value("reference", std::string()).find("truth look"), std::string::npos) << look.dump(1);
  EXPECT_FALSE(look.contains("truth_error"));
  EXPECT_EQ(look.value("truth_noise", -1.0), 0.005);  // the destination's background matched it
  ASSERT_TRUE(look.contains("own_photos"));
  EXPECT_GT(look["shading_mean"].get<double>(), 0.0);
  EXPECT_GT(look["own_photos"]["shading_mean"].get<double>(), 0.0);
  ASSERT_TRUE(look.contains("texture_corr"));
  EXPECT_GT(look["texture_corr"].get<double>(), 0.5);  // orange's peel carried through the map
  ASSERT_TRUE(r->quality.has_value());
  EXPECT_DOUBLE_EQ(look["coverage"].get<double>(), r->quality->coverage);
  EXPECT_DOUBLE_EQ(look["coherence"].get<double>(), r->quality->coherence);
  EXPECT_FALSE(look.contains("floor"));  // only when asked
  // the bull's set has no mask, so look.py compares every pixel, most of them
  // background copied from the destination; over the object the error is larger
  ASSERT_TRUE(look.contains("object"));
  EXPECT_GT(look["object"]["shading_mean"].get<double>(), 2 * look["shading_mean"].get<double>());

  // The figures are eval::look's on the written files (16-bit pictures), against
  // the truth look written as `veneer simulate --material` writes it.
  const fs::path dir = fs::temp_directory_path() / ("veneer-transfer-look-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  sim::RenderOptions o;
  o.size = dst.size;
  o.noise_sigma = 0.005;
  auto truth = sim::simulate_set_with_material("bull", "orange", o, io::Role::destination);
  ASSERT_TRUE(truth.ok());
  ASSERT_TRUE(write_transfer(*r, dir / "out").ok());
  ASSERT_TRUE(io::write_set(*truth, dir / "truth").ok());
  ASSERT_TRUE(io::write_set(dst, dir / "bull").ok());
  ASSERT_TRUE(io::write_set(src, dir / "orange").ok());
  auto files = eval::look_folders(dir / "out", dir / "truth", dir / "orange");
  ASSERT_TRUE(files.ok()) << files.message();
  EXPECT_NEAR(look["shading_mean"].get<double>(), files->shading.mean, 1e-3);
  EXPECT_NEAR(look["shading_p90"].get<double>(), files->shading.p90, 1e-3);
  EXPECT_NEAR(look["texture_corr"].get<double>(), *files->texture_corr, 1e-3);
  auto own = eval::look_folders(dir / "out", dir / "bull");
  ASSERT_TRUE(own.ok()) << own.message();
  EXPECT_NEAR(look["own_photos"]["shading_mean"].get<double>(), own->shading.mean, 1e-3);
  fs::remove_all(dir);
}

TEST(TransferLook, ANoiselessDestinationGetsANoiselessTruthLook) {
  const io::ImageSet dst = simulated("bull", io::Role::destination), src = simulated("orange", io::Role::source);
  auto r = transfer(dst, src, method(match::Method::linear));
  ASSERT_TRUE(r.ok()) << r.message();
  const nlohmann::json look = look_of(*r);
  EXPECT_NE(look.value("reference", std::string()).find("truth look"), std::string::npos) << look.dump(1);
  EXPECT_EQ(look.value("truth_noise", -1.0), 0.0);
}

TEST(TransferLook, RealPairIsScoredAgainstItsOwnPhotos) {
  io::ImageSet dst = simulated("bull", io::Role::destination), src = simulated("orange", io::Role::source);
  dst.scene.clear();  // as a real capture: no scene to render
  auto r = transfer(dst, src, method(match::Method::linear));
  ASSERT_TRUE(r.ok()) << r.message();
  const nlohmann::json look = look_of(*r);
  EXPECT_EQ(look.value("reference", std::string()), "the destination's own photos");
  EXPECT_FALSE(look.contains("own_photos"));
  EXPECT_GT(look["shading_mean"].get<double>(), 0.0);
}

TEST(TransferLook, ATruthLookThatDoesNotLineUpIsNotUsed) {
  // the destination posed 2 cm to the right: the truth look, rendered where
  // `veneer simulate` puts the bull by default, is another picture
  const io::ImageSet dst = simulated("bull", io::Role::destination, {0.02, 0, 0});
  const io::ImageSet src = simulated("orange", io::Role::source);
  auto r = transfer(dst, src, method(match::Method::linear));
  ASSERT_TRUE(r.ok()) << r.message();
  const nlohmann::json look = look_of(*r);
  EXPECT_NE(look.value("truth_error", std::string()).find("does not line up"), std::string::npos) << look.dump(1);
  EXPECT_EQ(look.value("reference", std::string()), "the destination's own photos");
}

TEST(TransferLook, PicturesNotKeptScoreTheSame) {
  const io::ImageSet dst = simulated("bull", io::Role::destination), src = simulated("orange", io::Role::source);
  TransferOptions o = method(match::Method::coherent);
  auto kept = transfer(dst, src, o);
  o.keep_pictures = false;
  auto painted_again = transfer(dst, src, o);
  ASSERT_TRUE(kept.ok() && painted_again.ok());
  ASSERT_TRUE(painted_again->repainted.empty());
  const nlohmann::json a = look_of(*kept), b = look_of(*painted_again);
  EXPECT_DOUBLE_EQ(a["shading_mean"].get<double>(), b["shading_mean"].get<double>());
  EXPECT_DOUBLE_EQ(a["own_photos"]["shading_p90"].get<double>(), b["own_photos"]["shading_p90"].get<double>());
}

TEST(TransferLook, TheFloorIsTheLinearMapsCopy) {
  const io::ImageSet dst = simulated("bull", io::Role::destination), src = simulated("orange", io::Role::source);
  TransferOptions o = method(match::Method::linear);
  o.look_floor = true;
  auto linear = transfer(dst, src, o);
  ASSERT_TRUE(linear.ok()) << linear.message();
  nlohmann::json look = look_of(*linear);
  ASSERT_TRUE(look.contains("floor")) << look.dump(1);
  // the linear transfer is its own floor
  EXPECT_NEAR(look["shading_vs_floor"].get<double>(), 1.0, 1e-9);
  EXPECT_DOUBLE_EQ(look["floor"]["coherence"].get<double>(), look["coherence"].get<double>());
  // another map's ratio is its shading over the floor's
  o.match.method = match::Method::coherent;
  auto coherent = transfer(dst, src, o);
  ASSERT_TRUE(coherent.ok()) << coherent.message();
  look = look_of(*coherent);
  ASSERT_TRUE(look.contains("floor"));
  EXPECT_EQ(look["floor"]["method"], "linear");
  EXPECT_NEAR(look["shading_vs_floor"].get<double>(),
              look["shading_mean"].get<double>() / look["floor"]["shading_mean"].get<double>(), 1e-12);
  EXPECT_GT(look["coherence"].get<double>(), look["floor"]["coherence"].get<double>());
}

}  // namespace
}  // namespace veneer::pipeline

namespace veneer::pipeline {
namespace {

// Issue 48: the CLI's transfer measures the quality against the truth right
// after the map and lets the truth go before the look is made; the result
// is the one transfer() gives.
TEST(TransferLook, ReleasingTheTruthEarlyGivesTheSameResult) {
  const io::ImageSet dst = simulated("bull", io::Role::destination, {0, 0, 0}, 0.005);
  const io::ImageSet src = simulated("orange", io::Role::source, {0, 0, 0}, 0.005);
  TransferOptions o = default_transfer_options();
  o.look_figures = false;
  auto kept = prepare_pair(dst, src, o);
  auto given = prepare_pair(dst, src, o);
  ASSERT_TRUE(kept.ok() && given.ok());
  auto a = transfer(*kept, o);
  auto b = transfer_releasing_truth(*given, o);
  ASSERT_TRUE(a.ok() && b.ok()) << (a.ok() ? b.message() : a.message());
  EXPECT_TRUE(kept->destination.truth.present());
  EXPECT_FALSE(given->destination.truth.present());
  EXPECT_FALSE(given->source.truth.present());
  ASSERT_TRUE(a->quality && b->quality);
  EXPECT_EQ(a->quality->coverage, b->quality->coverage);
  EXPECT_EQ(a->quality->coherence, b->quality->coherence);
  EXPECT_EQ(a->quality->normal_mean_deg, b->quality->normal_mean_deg);
  EXPECT_EQ(cv::norm(a->map.xy, b->map.xy, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(a->repainted_median, b->repainted_median, cv::NORM_INF), 0.0);
  const nlohmann::json ja = nlohmann::json::parse(a->metrics_json), jb = nlohmann::json::parse(b->metrics_json);
  EXPECT_EQ(ja["quality"], jb["quality"]);
  EXPECT_FALSE(ja.contains("look"));  // not asked for
  // with the look's figures asked for, the truth stays for them
  o.look_figures = true;
  auto again = prepare_pair(dst, src, o);
  ASSERT_TRUE(again.ok());
  auto c = transfer_releasing_truth(*again, o);
  ASSERT_TRUE(c.ok()) << c.message();
  EXPECT_TRUE(again->destination.truth.present());
  EXPECT_TRUE(nlohmann::json::parse(c->metrics_json).contains("look"));
}

}  // namespace
}  // namespace veneer::pipeline
