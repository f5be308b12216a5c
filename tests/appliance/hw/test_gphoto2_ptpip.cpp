// The gphoto2 camera back-end driving the real libgphoto2 (camlib ptp2, port
// driver ptpip) over PTP/IP on loopback against the PTP/IP camera twin: no
// seam is faked. Open, describe, exposure, capture + download + delete, live
// view, a whole set through the rig (Hue emulator lamps, simulator renders,
// the store), and the connection dropped mid-set.
//
// libgphoto2 keeps a GUID and settings in $HOME/.gphoto/settings: every test
// process gets a HOME of its own in a temporary folder.
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <random>
#include <thread>

#include <opencv2/imgcodecs.hpp>

#include "veneerd/config.hpp"
#include "veneerd/sim/ptpip_twin.hpp"
#include "veneerd/sim/simulated_rig.hpp"
#include "veneerd/hw/gphoto2.hpp"
#include "veneerd/rig.hpp"
#include "veneerd/store.hpp"

namespace fs = std::filesystem;

namespace {

using veneerd::PtpipTwin;
using veneerd::PtpipTwinOptions;
using veneerd::hw::Gphoto2Camera;

fs::path temp_dir(const std::string& name) {
  fs::path p = fs::temp_directory_path() /
               ("veneer-ptpip-" + name + "-" + std::to_string(::getpid()) + "-" + std::to_string(std::random_device{}()));
  fs::remove_all(p);
  fs::create_directories(p);
  return p;
}

// A HOME of this process's own, set before libgphoto2 reads its settings.
class GphotoHome : public ::testing::Environment {
 public:
  void SetUp() override {
    home_ = temp_dir("home");
    ::setenv("HOME", home_.c_str(), 1);
  }
  void TearDown() override { fs::remove_all(home_); }
  static const fs::path& home() { return home_; }

 private:
  static inline fs::path home_;
};
[[maybe_unused]] auto* const gphoto_home = ::testing::AddGlobalTestEnvironment(new GphotoHome);

// libgphoto2 loads its port drivers from IOLIBS or its build-time folder.
bool ptpip_driver_present(std::string& where) {
  const char* env = std::getenv("IOLIBS");
  fs::path dir = env && *env ? fs::path(env) : fs::path(VENEER_GPHOTO2_IOLIBS);
  where = (dir / "ptpip.so").string();
  return fs::exists(dir / "ptpip.so");
}

#define REQUIRE_PTPIP_DRIVER()                                                                                     \
  do {                                                                                                             \
    std::string where;                                                                                             \
    if (!ptpip_driver_present(where))                                                                              \
      GTEST_SKIP() << "libgphoto2's PTP/IP port driver is not installed (no " << where                             \
                   << "); it comes with libgphoto2's port library package";                                        \
  } while (0)

// Shot k: a 160x120 JPEG whose grey level and stripe position encode k.
std::vector<unsigned char> numbered_jpeg(uint64_t k) {
  cv::Mat m(120, 160, CV_8UC3, cv::Scalar::all(double(40 + (k * 23) % 180)));
  cv::Mat stripe = m(cv::Rect(int((k * 17) % 150), 0, 10, 120));
  stripe.setTo(cv::Scalar(255, 255, 255));
  std::vector<unsigned char> out;
  cv::imencode(".jpg", m, out, {cv::IMWRITE_JPEG_QUALITY, 90});
  return out;
}

std::vector<unsigned char> preview_jpeg() {
  std::vector<unsigned char> out;
  cv::imencode(".jpg", cv::Mat(90, 120, CV_8UC3, cv::Scalar(30, 60, 90)), out, {cv::IMWRITE_JPEG_QUALITY, 80});
  return out;
}

PtpipTwinOptions numbered_twin() {
  PtpipTwinOptions o;
  o.shot = [](const veneerd::PtpipExposure&, uint64_t k) -> veneer::Expected<std::vector<unsigned char>> {
    return numbered_jpeg(k);
  };
  o.preview = [](const veneerd::PtpipExposure&) -> veneer::Expected<std::vector<unsigned char>> {
    return preview_jpeg();
  };
  // The body starts in aperture priority with autofocus, as a camera is usually left.
  o.initial.program = 3;
  o.initial.focus = 2;
  return o;
}

std::unique_ptr<PtpipTwin> start_twin(PtpipTwinOptions o) {
  auto t = PtpipTwin::start(std::move(o));
  if (!t) {
    ADD_FAILURE() << t.message();
    return nullptr;
  }
  return std::move(*t);
}

// The camera as veneerd builds it from its config section.
std::unique_ptr<Gphoto2Camera> camera_for(const PtpipTwin& twin, nlohmann::json extra = nlohmann::json::object()) {
  nlohmann::json section = {{"backend", "gphoto2"}, {"port", twin.gphoto2_port()}, {"reopen_delay_ms", 100}};
  for (auto& [k, v] : extra.items()) section[k] = v;
  auto o = veneerd::hw::parse_gphoto2_options(section, "camera");
  if (!o) {
    ADD_FAILURE() << o.message();
    return nullptr;
  }
  return std::make_unique<Gphoto2Camera>(veneerd::hw::make_libgphoto2_api(), nullptr, *o);
}

bool has_write(const PtpipTwin& twin, uint16_t code, uint32_t value) {
  for (auto [c, v] : twin.property_writes())
    if (c == code && v == value) return true;
  return false;
}

TEST(Gphoto2OverPtpip, OpensAndDescribesTheTwin) {
  REQUIRE_PTPIP_DRIVER();
  auto twin = start_twin(numbered_twin());
  ASSERT_TRUE(twin);
  auto camera = camera_for(*twin);
  ASSERT_TRUE(camera);
  auto opened = camera->open();
  ASSERT_TRUE(opened.ok()) << opened.message();
  EXPECT_TRUE(camera->connected());
  auto d = camera->describe();
  ASSERT_TRUE(d.ok()) << d.message();
  EXPECT_EQ(d->model, "Veneer PTP/IP twin");  // the body's device info, not the driver's name
  EXPECT_EQ(d->shutter_values.size(), 10u);
  EXPECT_NE(std::find(d->shutter_values.begin(), d->shutter_values.end(), "0.0167s"), d->shutter_values.end());
  EXPECT_EQ(d->aperture_values.front(), "f/2.8");
  EXPECT_EQ(d->iso_values.back(), "3200");
  // Opening put the body in M with autofocus off, through SetDevicePropValue.
  EXPECT_EQ(twin->exposure().program, 1);
  EXPECT_EQ(twin->exposure().focus, 1);
  EXPECT_EQ(twin->stats().sessions, 1u);
  // libgphoto2's PTP/IP GUID went into this test's own HOME.
  EXPECT_TRUE(fs::exists(GphotoHome::home() / ".gphoto" / "settings"));
}

TEST(Gphoto2OverPtpip, ExposureReachesTheBody) {
  REQUIRE_PTPIP_DRIVER();
  auto twin = start_twin(numbered_twin());
  ASSERT_TRUE(twin);
  auto camera = camera_for(*twin);
  ASSERT_TRUE(camera);
  auto s = camera->set_exposure({1.0 / 125, 11, 400});
  ASSERT_TRUE(s.ok()) << s.message();
  auto e = twin->exposure();
  EXPECT_EQ(e.exposure_time, 80u);  // 1/125 s in 1/10000 s
  EXPECT_EQ(e.f_number, 1100);
  EXPECT_EQ(e.iso, 400);
  EXPECT_TRUE(has_write(*twin, 0x500D, 80));
  EXPECT_TRUE(has_write(*twin, 0x5007, 1100));
  EXPECT_TRUE(has_write(*twin, 0x500F, 400));
  s = camera->set_exposure({1.0 / 60, 5.6, 200});
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(twin->exposure().exposure_time, 167u);
  EXPECT_EQ(twin->exposure().f_number, 560);
  EXPECT_EQ(twin->exposure().iso, 200);
  // A value the body does not offer is refused by name, and nothing changes.
  auto bad = camera->set_exposure({0, 6.3, 0});
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("f/6.3 is not offered"), std::string::npos) << bad.message();
  EXPECT_NE(bad.message().find("f/5.6, f/8"), std::string::npos) << bad.message();
  EXPECT_EQ(twin->exposure().f_number, 560);
}

TEST(Gphoto2OverPtpip, CaptureDownloadsTheServedBytesAndDeletesThem) {
  REQUIRE_PTPIP_DRIVER();
  auto twin = start_twin(numbered_twin());
  ASSERT_TRUE(twin);
  auto camera = camera_for(*twin, {{"still_size", {160, 120}}});
  ASSERT_TRUE(camera);
  for (int k = 1; k <= 3; ++k) {
    auto still = camera->capture();
    ASSERT_TRUE(still.ok()) << "shot " << k << ": " << still.message();
    auto files = twin->files();
    ASSERT_EQ(files.size(), size_t(k));
    EXPECT_EQ(still->original_name, files.back().name);
    EXPECT_EQ(still->original, files.back().bytes) << "shot " << k << " differs from what the twin served";
    EXPECT_EQ(still->original, numbered_jpeg(uint64_t(k)));
    EXPECT_EQ(still->linear.size(), cv::Size(160, 120));
    EXPECT_EQ(files.back().downloads, 1);
  }
  EXPECT_EQ(twin->files().front().name, "IMG_0001.JPG");
  // keep_on_card is false: every shot was deleted after its download.
  EXPECT_TRUE(twin->files_on_card().empty());
  EXPECT_EQ(twin->stats().deletes, 3u);
  EXPECT_EQ(twin->stats().captures, 3u);
}

TEST(Gphoto2OverPtpip, KeepOnCardLeavesTheShots) {
  REQUIRE_PTPIP_DRIVER();
  auto twin = start_twin(numbered_twin());
  ASSERT_TRUE(twin);
  auto camera = camera_for(*twin, {{"keep_on_card", true}, {"still_size", {160, 120}}});
  ASSERT_TRUE(camera);
  for (int k = 1; k <= 2; ++k) {
    auto still = camera->capture();
    ASSERT_TRUE(still.ok()) << still.message();
  }
  EXPECT_EQ(twin->files_on_card(), (std::vector<std::string>{"IMG_0001.JPG", "IMG_0002.JPG"}));
  EXPECT_EQ(twin->stats().deletes, 0u);
}

TEST(Gphoto2OverPtpip, LiveViewThroughPtpStreams) {
  REQUIRE_PTPIP_DRIVER();
  auto twin = start_twin(numbered_twin());
  ASSERT_TRUE(twin);
  auto camera = camera_for(*twin);
  ASSERT_TRUE(camera);
  for (int i = 0; i < 3; ++i) {
    auto frame = camera->preview();
    ASSERT_TRUE(frame.ok()) << frame.message();
    EXPECT_EQ(*frame, preview_jpeg());
  }
  EXPECT_EQ(twin->stats().stream_frames, 3u);
  EXPECT_TRUE(has_write(*twin, 0x5021, 1));  // EnabledStreams: video on
}

TEST(Gphoto2OverPtpip, WithoutStreamsLiveViewIsNotSupported) {
  REQUIRE_PTPIP_DRIVER();
  auto o = numbered_twin();
  o.preview = nullptr;
  auto twin = start_twin(o);
  ASSERT_TRUE(twin);
  auto camera = camera_for(*twin);
  ASSERT_TRUE(camera);
  auto frame = camera->preview();
  ASSERT_FALSE(frame.ok());
  EXPECT_NE(frame.message().find("live view"), std::string::npos) << frame.message();
  // Stills still work, at their own size.
  auto still = camera->capture();
  ASSERT_TRUE(still.ok()) << still.message();
  EXPECT_EQ(still->linear.size(), cv::Size(160, 120));
}

TEST(Gphoto2OverPtpip, ALostConnectionIsReopenedOnUse) {
  REQUIRE_PTPIP_DRIVER();
  auto twin = start_twin(numbered_twin());
  ASSERT_TRUE(twin);
  auto camera = camera_for(*twin, {{"still_size", {160, 120}}});
  ASSERT_TRUE(camera);
  ASSERT_TRUE(camera->open().ok());
  twin->drop_now();  // the camera's Wi-Fi went away between two sets
  auto s = camera->set_exposure({1.0 / 250, 8, 100});
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(twin->exposure().exposure_time, 40u);
  twin->drop_now();
  auto still = camera->capture();
  ASSERT_TRUE(still.ok()) << still.message();
  EXPECT_EQ(still->original, twin->files().back().bytes);
  EXPECT_EQ(twin->stats().connections, 3u);
}

TEST(Gphoto2OverPtpip, ACameraThatIsOffIsNamed) {
  REQUIRE_PTPIP_DRIVER();
  auto twin = start_twin(numbered_twin());
  ASSERT_TRUE(twin);
  twin->set_on(false);
  auto camera = camera_for(*twin);
  ASSERT_TRUE(camera);
  auto s = camera->open();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("no PTP/IP camera answered at 127.0.0.1:" + std::to_string(twin->port())),
            std::string::npos)
      << s.message();
  EXPECT_FALSE(camera->connected());
  twin->set_on(true);
  s = camera->open();
  EXPECT_TRUE(s.ok()) << s.message();
}

// A raw TCP connection to the twin; -1 on failure.
int connect_to(uint16_t port) {
  int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (fd >= 0 && ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0) return fd;
  if (fd >= 0) ::close(fd);
  return -1;
}

// Reads until the twin closes the connection; the bytes it sent.
std::vector<uint8_t> read_to_end(int fd) {
  std::vector<uint8_t> got;
  uint8_t buf[256];
  ssize_t n;
  while ((n = ::recv(fd, buf, sizeof buf, 0)) > 0) got.insert(got.end(), buf, buf + n);
  return got;
}

TEST(PtpipTwin, SurvivesMalformedInitiators) {
  REQUIRE_PTPIP_DRIVER();
  auto twin = start_twin(numbered_twin());
  ASSERT_TRUE(twin);
  // A length shorter than a header, an absurd length, a first packet that is
  // no Init request, an Init Event Request for no command connection.
  const std::vector<std::vector<uint8_t>> garbage = {
      {3, 0, 0, 0, 1, 0, 0, 0},
      {0xff, 0xff, 0xff, 0x7f, 1, 0, 0, 0},
      {8, 0, 0, 0, 6, 0, 0, 0},
      {12, 0, 0, 0, 3, 0, 0, 0, 99, 0, 0, 0},
  };
  for (size_t i = 0; i < garbage.size(); ++i) {
    int fd = connect_to(twin->port());
    ASSERT_GE(fd, 0);
    ASSERT_EQ(::send(fd, garbage[i].data(), garbage[i].size(), MSG_NOSIGNAL), ssize_t(garbage[i].size()));
    auto reply = read_to_end(fd);  // the twin closes the connection
    ::close(fd);
    if (i == 3) {
      ASSERT_GE(reply.size(), 8u);
      EXPECT_EQ(reply[4], 5) << "Init Fail";
    }
  }
  // It still serves a real initiator.
  auto camera = camera_for(*twin, {{"still_size", {160, 120}}});
  ASSERT_TRUE(camera);
  auto still = camera->capture();
  ASSERT_TRUE(still.ok()) << still.message();
  EXPECT_EQ(still->original, numbered_jpeg(1));
  EXPECT_EQ(twin->stats().connections, 1u);
}

// ----------------------------------------------------------------- whole sets

// The rig of veneerd, in this process: Hue lamps through libcurl to the bridge
// emulator, the gphoto2 camera through libgphoto2 to the twin, which renders
// with the simulator under the lamps the bridge reports on.
struct PtpipRig {
  static constexpr int kLamps = 4;
  fs::path dir;
  std::unique_ptr<veneerd::SimulatedRig> sim;
  std::shared_ptr<veneerd::SimulatedCamera> renderer;
  std::unique_ptr<PtpipTwin> twin;
  std::unique_ptr<veneerd::Store> store;
  std::unique_ptr<veneerd::Rig> rig;
  std::mutex mu;
  std::condition_variable cv;
  std::vector<veneerd::RigEvent> events;

  bool start(nlohmann::json camera_extra = nlohmann::json::object()) {
    dir = temp_dir("rig");
    veneerd::SimulatedRigOptions so;
    so.scenes = {"sphere-gray"};
    so.lamps = kLamps;
    so.size = {128, 85};
    so.preview_size = {128, 85};
    so.noise_sigma = 0;
    so.apply_delay_ms = 20;
    so.settle_ms = 40;
    so.latency_ms = 0;
    so.rate_limits = false;
    auto s = veneerd::SimulatedRig::start(so);
    if (!s) return fail(s.message());
    sim = std::move(*s);
    auto cam = sim->make_camera();
    if (!cam) return fail(cam.message());
    renderer = std::shared_ptr<veneerd::SimulatedCamera>(std::move(*cam));
    PtpipTwinOptions to;
    to.shot = veneerd::simulated_shot_source(renderer);
    to.preview = veneerd::simulated_preview_source(renderer);
    auto t = PtpipTwin::start(to);
    if (!t) return fail(t.message());
    twin = std::move(*t);
    auto st = veneerd::Store::open(dir / "store");
    if (!st) return fail(st.message());
    store = std::move(*st);

    veneerd::RigDevices devices;
    auto lamps = sim->make_lamps();
    if (!lamps) return fail(lamps.message());
    devices.lamps = std::move(*lamps);
    camera_extra["still_size"] = {128, 85};
    devices.camera = camera_for(*twin, camera_extra);
    if (!devices.camera) return false;
    veneerd::RigOptions ro;
    ro.lamp_ids = sim->context().lamp_ids;
    auto ring = veneerd::thesis_ring_positions();
    ro.lamp_positions.assign(ring.begin(), ring.begin() + kLamps);
    ro.exposure = {1.0 / 30, 8, 100};
    ro.settle_ms = 40;
    rig = std::make_unique<veneerd::Rig>(std::move(devices), *store, ro);
    rig->on_event = [this](const veneerd::RigEvent& e) {
      std::lock_guard l(mu);
      events.push_back(e);
      cv.notify_all();
    };
    rig->start();
    return true;
  }
  bool fail(const std::string& why) {
    ADD_FAILURE() << why;
    return false;
  }
  ~PtpipRig() {
    if (rig) rig->stop();
    rig.reset();
    store.reset();
    twin.reset();
    renderer.reset();
    sim.reset();
    fs::remove_all(dir);
  }
  // Captures a set; the event that ended it (set_stored or capture_failed).
  std::optional<veneerd::RigEvent> capture() {
    size_t seen = 0;  // set ids are made of the second and the role: only events from now on count
    {
      std::lock_guard l(mu);
      seen = events.size();
    }
    auto id = rig->capture({veneer::io::Role::destination, "sphere", {}});
    if (!id) {
      ADD_FAILURE() << id.message();
      return std::nullopt;
    }
    std::unique_lock l(mu);
    std::optional<veneerd::RigEvent> end;
    // Generous: a loaded 2-core machine renders and reconnects slowly.
    cv.wait_for(l, std::chrono::seconds(120), [&] {
      for (size_t i = seen; i < events.size(); ++i)
        if (const auto& e = events[i]; e.set_id == *id &&
            (e.kind == veneerd::RigEvent::Kind::set_stored || e.kind == veneerd::RigEvent::Kind::capture_failed)) {
          end = e;
          return true;
        }
      return false;
    });
    if (!end) ADD_FAILURE() << "capture " << *id << " did not end within 120 s";
    return end;
  }
  // Every entry of the store folder but its lock file.
  std::vector<std::string> store_entries() const {
    std::vector<std::string> out;
    for (const auto& e : fs::directory_iterator(dir / "store"))
      if (e.path().filename() != ".lock") out.push_back(e.path().filename().string());
    return out;
  }
};

double mean_of(const cv::Mat& m) {
  cv::Scalar s = cv::mean(m);
  return (s[0] + s[1] + s[2]) / 3;
}

TEST(Gphoto2OverPtpip, AWholeSetThroughTheRigAndTheStore) {
  REQUIRE_PTPIP_DRIVER();
  PtpipRig r;
  ASSERT_TRUE(r.start());
  auto end = r.capture();
  ASSERT_TRUE(end);
  ASSERT_EQ(end->kind, veneerd::RigEvent::Kind::set_stored) << end->reason;
  // Ambient + one shot per lamp, each downloaded once and deleted from the card.
  auto files = r.twin->files();
  ASSERT_EQ(files.size(), size_t(PtpipRig::kLamps + 1));
  for (const auto& f : files) {
    EXPECT_EQ(f.downloads, 1) << f.name;
    EXPECT_TRUE(f.deleted) << f.name;
    EXPECT_EQ(f.exposure.exposure_time, 333u) << f.name;  // 1/30 s, as the rig asked
    EXPECT_EQ(f.exposure.f_number, 800) << f.name;
    EXPECT_EQ(f.exposure.iso, 100) << f.name;
  }
  EXPECT_TRUE(r.twin->files_on_card().empty());
  // The stored set holds exactly the served shots (decoded the way the back-end decodes).
  auto stored = r.store->list();
  ASSERT_EQ(stored.size(), 1u);
  auto set = veneer::io::read_set(r.store->folder(stored[0].id));
  ASSERT_TRUE(set.ok()) << set.message();
  ASSERT_EQ(set->images.size(), size_t(PtpipRig::kLamps));
  EXPECT_EQ(set->camera.model, "Veneer PTP/IP twin");
  auto served = [&](size_t i) {
    auto m = veneerd::hw::decode_jpeg_linear(files[i].bytes, {128, 85});
    EXPECT_TRUE(m.ok()) << m.message();
    return m.ok() ? *m : cv::Mat();
  };
  // 16-bit PNG storage: equal to 1/65535.
  EXPECT_LT(cv::norm(set->ambient, served(0), cv::NORM_INF), 2.0 / 65535) << "ambient";
  for (int i = 0; i < PtpipRig::kLamps; ++i)
    EXPECT_LT(cv::norm(set->images[i], served(i + 1), cv::NORM_INF), 2.0 / 65535) << "lamp " << i + 1;
  // The ambient frame was taken with every lamp off, each shot with a lamp on.
  for (int i = 0; i < PtpipRig::kLamps; ++i)
    EXPECT_LT(mean_of(set->ambient) * 5, mean_of(set->images[i])) << "lamp " << i + 1;
}

TEST(Gphoto2OverPtpip, ADropMidSetReconnectsAndRetakesTheShot) {
  REQUIRE_PTPIP_DRIVER();
  PtpipRig r;
  ASSERT_TRUE(r.start());
  r.twin->drop_at(PtpipTwin::DropAt::download, 3);  // the third download dies halfway
  auto end = r.capture();
  ASSERT_TRUE(end);
  ASSERT_EQ(end->kind, veneerd::RigEvent::Kind::set_stored) << end->reason;
  auto stats = r.twin->stats();
  EXPECT_EQ(stats.drops, 1u);
  EXPECT_EQ(stats.connections, 2u);
  // Shot 3 was taken twice: the first copy stays on the card, undelivered.
  auto files = r.twin->files();
  ASSERT_EQ(files.size(), size_t(PtpipRig::kLamps + 2));
  EXPECT_EQ(files[2].downloads, 0);
  EXPECT_EQ(r.twin->files_on_card(), std::vector<std::string>{files[2].name});
  auto stored = r.store->list();
  ASSERT_EQ(stored.size(), 1u);
  auto set = veneer::io::read_set(r.store->folder(stored[0].id));
  ASSERT_TRUE(set.ok()) << set.message();
  auto retaken = veneerd::hw::decode_jpeg_linear(files[3].bytes, {128, 85});
  ASSERT_TRUE(retaken.ok());
  EXPECT_LT(cv::norm(set->images[1], *retaken, cv::NORM_INF), 2.0 / 65535);  // shot 3 = lamp 2
}

TEST(Gphoto2OverPtpip, ADropMidSetWithTheCameraOffFailsCleanlyThenRecovers) {
  REQUIRE_PTPIP_DRIVER();
  PtpipRig r;
  ASSERT_TRUE(r.start());
  r.twin->drop_at(PtpipTwin::DropAt::capture, 3, /*stay_off=*/true);  // unplugged while exposing shot 3
  auto end = r.capture();
  ASSERT_TRUE(end);
  ASSERT_EQ(end->kind, veneerd::RigEvent::Kind::capture_failed);
  EXPECT_NE(end->reason.find("shot 3 of 5"), std::string::npos) << end->reason;
  EXPECT_NE(end->reason.find("reconnecting failed"), std::string::npos) << end->reason;
  EXPECT_NE(end->reason.find("no PTP/IP camera answered"), std::string::npos) << end->reason;
  // Nothing half-written: no set, no temporary folder.
  EXPECT_TRUE(r.store->list().empty());
  EXPECT_TRUE(r.store_entries().empty()) << r.store_entries().front();
  EXPECT_FALSE(r.rig->state().camera_connected);
  // The camera comes back: the next set reconnects and is stored whole.
  r.twin->set_on(true);
  end = r.capture();
  ASSERT_TRUE(end);
  ASSERT_EQ(end->kind, veneerd::RigEvent::Kind::set_stored) << end->reason;
  ASSERT_EQ(r.store->list().size(), 1u);
  EXPECT_EQ(r.store->list()[0].lights, PtpipRig::kLamps);
  EXPECT_TRUE(r.rig->state().camera_connected);
}

}  // namespace
