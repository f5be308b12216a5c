// The gphoto2 camera back-end through a fake of the gphoto2 surface.
#include <gtest/gtest.h>

#include <atomic>
#include <future>
#include <random>

#include <opencv2/imgcodecs.hpp>

#include "fake_gphoto2.hpp"
#include "veneerd/hw/gphoto2.hpp"

namespace veneerd::hw {
namespace {

using testing::FakeBody;
using testing::FakeGphoto2;
using testing::radio;

std::vector<unsigned char> jpeg_of(const cv::Mat& img) {
  std::vector<unsigned char> out;
  cv::imencode(".jpg", img, out, {cv::IMWRITE_JPEG_QUALITY, 100});
  return out;
}

// 256x170: left half sRGB 128 grey, right half white.
cv::Mat test_still() {
  cv::Mat m(170, 256, CV_8UC3, cv::Scalar(128, 128, 128));
  m(cv::Rect(128, 0, 128, 170)).setTo(cv::Scalar(255, 255, 255));
  return m;
}

FakeBody canon() {
  FakeBody b;
  b.model = "Canon EOS 600D";
  b.settings["autoexposuremode"] = radio("AV", {"P", "TV", "AV", "Manual", "Bulb"});
  b.settings["focusmode"] = radio("One Shot", {"One Shot", "AI Servo", "Manual"});
  b.settings["capturetarget"] = radio("Memory card", {"Internal RAM", "Memory card"});
  b.settings["aperture"] = radio("5.6", {"4", "4.5", "5", "5.6", "6.3", "7.1", "8", "9", "10", "11"});
  b.settings["shutterspeed"] = radio("1/60", {"bulb", "30", "2", "1", "0.5", "0.3", "1/4", "1/60", "1/125", "1/250"});
  b.settings["iso"] = radio("Auto", {"Auto", "100", "200", "400", "800"});
  b.shot_files = {{"IMG_0001.JPG", jpeg_of(test_still())}};
  b.preview_jpeg = jpeg_of(cv::Mat(85, 128, CV_8UC3, cv::Scalar(60, 60, 60)));
  return b;
}

FakeBody nikon() {
  FakeBody b;
  b.model = "Nikon DSC D7100";
  b.port = "usb:002,009";
  b.settings["expprogram"] = radio("M", {"M", "P", "A", "S", "Auto"});
  b.settings["f-number"] = radio("f/4", {"f/4", "f/5.6", "f/8", "f/11", "f/16"});
  b.settings["shutterspeed2"] = radio("1/30", {"1/30", "1/60", "1/125", "1/250", "2", "10"});
  b.settings["iso"] = radio("100", {"100", "200", "400"});
  b.shot_files = {{"DSC_0001.JPG", jpeg_of(test_still())}};
  b.preview_jpeg = jpeg_of(cv::Mat(85, 128, CV_8UC3, cv::Scalar(60, 60, 60)));
  return b;
}

struct Harness {
  FakeGphoto2* fake;
  std::unique_ptr<Gphoto2Camera> camera;
  std::vector<bool> changes;
  std::mutex mu;
  explicit Harness(FakeBody body, Gphoto2Options opt = {}) {
    auto f = std::make_unique<FakeGphoto2>(std::move(body));
    fake = f.get();
    opt.reopen_delay_ms = 0;
    opt.paired_jpeg_wait_ms = 50;
    camera = std::make_unique<Gphoto2Camera>(std::move(f), nullptr, opt);
    camera->on_connection_change = [this](bool c) {
      std::lock_guard<std::mutex> l(mu);
      changes.push_back(c);
    };
  }
  std::vector<bool> seen() {
    std::lock_guard<std::mutex> l(mu);
    return changes;
  }
};

TEST(Gphoto2, OpenPutsBodyInManualModeWithAutofocusOff) {
  Harness h(canon());
  ASSERT_TRUE(h.camera->open().ok());
  EXPECT_TRUE(h.camera->connected());
  EXPECT_EQ(h.fake->setting("autoexposuremode"), "Manual");
  EXPECT_EQ(h.fake->setting("focusmode"), "Manual");
  EXPECT_EQ(h.fake->setting("capturetarget"), "Internal RAM");
  // The session is kept: a second open does not re-initialise.
  ASSERT_TRUE(h.camera->open().ok());
  EXPECT_EQ(h.fake->opens, 1);
  EXPECT_EQ(h.seen(), std::vector<bool>{true});
}

TEST(Gphoto2, DescribeListsOfferedExposureValues) {
  Harness h(canon());
  auto d = h.camera->describe();
  ASSERT_TRUE(d.ok()) << d.message();
  EXPECT_EQ(d->model, "Canon EOS 600D");
  EXPECT_EQ(d->aperture_values.size(), 10u);
  EXPECT_EQ(d->shutter_values.front(), "bulb");
  EXPECT_EQ(d->iso_values.back(), "800");
}

TEST(Gphoto2, CanonNamesAperturAndShutterspeed) {
  Harness h(canon());
  ASSERT_TRUE(h.camera->set_exposure({1.0 / 125, 8.0, 200}).ok());
  EXPECT_EQ(h.fake->setting("aperture"), "8");
  EXPECT_EQ(h.fake->setting("shutterspeed"), "1/125");
  EXPECT_EQ(h.fake->setting("iso"), "200");
  // Rounded nominal values map to the camera's labels.
  ASSERT_TRUE(h.camera->set_exposure({1.0 / 3, 7.1, 0}).ok());
  EXPECT_EQ(h.fake->setting("shutterspeed"), "0.3");
  EXPECT_EQ(h.fake->setting("aperture"), "7.1");
}

TEST(Gphoto2, NikonNamesFNumberAndShutterspeed2) {
  Harness h(nikon());
  ASSERT_TRUE(h.camera->set_exposure({0.004, 5.6, 400}).ok());
  EXPECT_EQ(h.fake->setting("f-number"), "f/5.6");
  EXPECT_EQ(h.fake->setting("shutterspeed2"), "1/250");
  EXPECT_EQ(h.fake->setting("iso"), "400");
  ASSERT_TRUE(h.camera->set_exposure({2.0, 0, 0}).ok());
  EXPECT_EQ(h.fake->setting("shutterspeed2"), "2");
}

TEST(Gphoto2, ValueNotOfferedNamesTheOfferedValues) {
  Harness h(nikon());
  auto s = h.camera->set_exposure({0, 6.3, 0});
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("f/6.3"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("not offered"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("f/4, f/5.6, f/8, f/11, f/16"), std::string::npos) << s.message();
  EXPECT_EQ(h.fake->setting("f-number"), "f/4");  // unchanged
  auto iso = h.camera->set_exposure({0, 0, 3200});
  ASSERT_FALSE(iso.ok());
  EXPECT_NE(iso.message().find("ISO 3200"), std::string::npos) << iso.message();
  auto shutter = h.camera->set_exposure({1.0 / 8000, 0, 0});
  ASSERT_FALSE(shutter.ok());
  EXPECT_NE(shutter.message().find("1/8000"), std::string::npos) << shutter.message();
}

TEST(Gphoto2, ReadOnlyModeDialIsExplained) {
  FakeBody b = canon();
  b.settings["aperture"].readonly = true;
  Harness h(std::move(b));
  auto s = h.camera->set_exposure({0, 8, 0});
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("read-only"), std::string::npos) << s.message();
}

TEST(Gphoto2, DeviceHeldByAnotherProgram) {
  Harness h(canon());
  h.fake->open_error = gp::io_usb_claim;
  auto s = h.camera->open();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("held by another program"), std::string::npos) << s.message();
  EXPECT_FALSE(h.camera->connected());
  h.fake->open_error = gp::ok;  // the auto-mounter let go
  EXPECT_TRUE(h.camera->open().ok());
}

TEST(Gphoto2, NoCameraSaysSo) {
  Harness h(canon());
  h.fake->present = false;
  auto s = h.camera->capture();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("no camera found"), std::string::npos) << s.message();
}

TEST(Gphoto2, CaptureDownloadsLinearisesAndResizesToLiveView) {
  Harness h(canon());
  auto still = h.camera->capture();
  ASSERT_TRUE(still.ok()) << still.message();
  EXPECT_EQ(still->linear.type(), CV_32FC3);
  EXPECT_EQ(still->linear.size(), cv::Size(128, 85));  // the live-view size
  // sRGB 128 → linear 0.216, 255 → 1.0 (inverse sRGB curve, not gamma 2.2 or none).
  cv::Scalar left = cv::mean(still->linear(cv::Rect(8, 8, 48, 69)));
  cv::Scalar right = cv::mean(still->linear(cv::Rect(72, 8, 48, 69)));
  EXPECT_NEAR(left[1], 0.2158, 0.01);
  EXPECT_NEAR(right[1], 1.0, 0.01);
  EXPECT_EQ(still->original_name, "IMG_0001.JPG");
  cv::Mat full = cv::imdecode(still->original, cv::IMREAD_COLOR);
  EXPECT_EQ(full.size(), cv::Size(256, 170));  // the original is kept at full size
  EXPECT_EQ(h.fake->removed, std::vector<std::string>{"IMG_0001.JPG"});
}

TEST(Gphoto2, ConfiguredStillSizeWins) {
  Gphoto2Options o;
  o.still_width = 64;
  o.still_height = 64;
  Harness h(canon(), o);
  auto still = h.camera->capture();
  ASSERT_TRUE(still.ok()) << still.message();
  EXPECT_EQ(still->linear.size(), cv::Size(64, 43));  // fits inside, aspect kept
}

// A RAW file stand-in: a TIFF-like header, noise, a thumbnail and a large preview JPEG.
std::vector<unsigned char> fake_raw(const cv::Mat& preview) {
  std::mt19937 rng(7);
  std::vector<unsigned char> raw{'I', 'I', '*', 0};
  for (int i = 0; i < 5000; ++i) raw.push_back(static_cast<unsigned char>(rng() % 0xF0));
  auto thumb = jpeg_of(cv::Mat(10, 16, CV_8UC3, cv::Scalar(0, 0, 255)));
  raw.insert(raw.end(), thumb.begin(), thumb.end());
  for (int i = 0; i < 3000; ++i) raw.push_back(static_cast<unsigned char>(rng() % 0xF0));
  auto big = jpeg_of(preview);
  raw.insert(raw.end(), big.begin(), big.end());
  for (int i = 0; i < 2000; ++i) raw.push_back(static_cast<unsigned char>(rng() % 0xF0));
  return raw;
}

TEST(Gphoto2, EmbeddedJpegIsTheLargest) {
  cv::Mat preview = test_still();
  auto raw = fake_raw(preview);
  auto jpeg = embedded_jpeg(raw);
  EXPECT_EQ(jpeg, jpeg_of(preview));
  EXPECT_TRUE(embedded_jpeg(std::vector<unsigned char>(100, 0xFF)).empty());
  EXPECT_TRUE(is_raw_name("IMG_0001.CR2"));
  EXPECT_TRUE(is_raw_name("dsc_0001.nef"));
  EXPECT_FALSE(is_raw_name("IMG_0001.JPG"));
}

TEST(Gphoto2, RawPlusJpegUsesPairedJpegAndKeepsRaw) {
  FakeBody b = canon();
  cv::Mat embedded(170, 256, CV_8UC3, cv::Scalar(0, 0, 0));  // would read as black
  auto raw = fake_raw(embedded);
  b.shot_files = {{"IMG_0002.CR2", raw}, {"IMG_0002.JPG", jpeg_of(test_still())}};
  Harness h(std::move(b));
  auto still = h.camera->capture();
  ASSERT_TRUE(still.ok()) << still.message();
  EXPECT_EQ(still->original_name, "IMG_0002.CR2");
  EXPECT_EQ(still->original, raw);
  EXPECT_NEAR(cv::mean(still->linear(cv::Rect(72, 8, 48, 69)))[1], 1.0, 0.01);  // from the paired JPEG
  EXPECT_EQ(h.fake->removed.size(), 2u);
}

TEST(Gphoto2, RawOnlyFallsBackToEmbeddedJpeg) {
  FakeBody b = canon();
  auto raw = fake_raw(test_still());
  b.shot_files = {{"IMG_0003.CR2", raw}};
  Harness h(std::move(b));
  auto still = h.camera->capture();
  ASSERT_TRUE(still.ok()) << still.message();
  EXPECT_EQ(still->original, raw);
  EXPECT_NEAR(cv::mean(still->linear(cv::Rect(8, 8, 48, 69)))[1], 0.2158, 0.01);
}

TEST(Gphoto2, UnplugDuringCaptureFailsCleanlyAndReports) {
  Harness h(canon());
  ASSERT_TRUE(h.camera->open().ok());
  h.fake->block_capture = true;
  auto running = std::async(std::launch::async, [&] { return h.camera->capture(); });
  ASSERT_TRUE(h.fake->wait_capture_started(5000));
  // libusb reports the device gone, then the body stops answering.
  h.camera->usb_changed(false, {1, 5, 0x04a9, 0x3217});
  h.fake->unplug();
  auto still = running.get();
  ASSERT_FALSE(still.ok());
  EXPECT_NE(still.message().find("unplugged"), std::string::npos) << still.message();
  EXPECT_FALSE(h.camera->connected());
  EXPECT_EQ(h.seen(), (std::vector<bool>{true, false}));
  EXPECT_EQ(h.fake->closes, 1);  // the dead session was dropped
  // Further calls fail plainly instead of hanging.
  auto again = h.camera->capture();
  ASSERT_FALSE(again.ok());
  EXPECT_NE(again.message().find("no camera found"), std::string::npos) << again.message();
}

TEST(Gphoto2, OtherUsbDeviceLeavingIsIgnored) {
  Harness h(canon());
  ASSERT_TRUE(h.camera->open().ok());
  h.camera->usb_changed(false, {1, 7, 0x0781, 0x5567});  // a USB stick
  EXPECT_TRUE(h.camera->connected());
  EXPECT_TRUE(h.camera->capture().ok());
}

TEST(Gphoto2, ReopensAfterReplugWithoutRestart) {
  Harness h(canon());
  ASSERT_TRUE(h.camera->open().ok());
  h.camera->usb_changed(false, {1, 5, 0x04a9, 0x3217});
  h.fake->unplug();
  EXPECT_FALSE(h.camera->connected());
  // Plugged back: new address, as the kernel hands out.
  h.fake->replug("usb:001,006");
  h.camera->usb_changed(true, {1, 6, 0x04a9, 0x3217});
  ASSERT_TRUE(h.camera->wait_reopen_idle(5000));
  EXPECT_TRUE(h.camera->connected());
  EXPECT_EQ(h.seen(), (std::vector<bool>{true, false, true}));
  EXPECT_EQ(h.fake->opens, 2);
  auto still = h.camera->capture();
  ASSERT_TRUE(still.ok()) << still.message();
  // The new address is the one watched now.
  h.camera->usb_changed(false, {1, 5, 0x04a9, 0x3217});
  EXPECT_TRUE(h.camera->connected());
  h.camera->usb_changed(false, {1, 6, 0x04a9, 0x3217});
  EXPECT_FALSE(h.camera->connected());
}

TEST(Gphoto2, PreviewReturnsCameraJpeg) {
  Harness h(canon());
  auto frame = h.camera->preview();
  ASSERT_TRUE(frame.ok()) << frame.message();
  EXPECT_EQ(cv::imdecode(*frame, cv::IMREAD_COLOR).size(), cv::Size(128, 85));
}

TEST(Gphoto2, MatchingRules) {
  std::vector<std::string> sh{"bulb", "30", "1/4", "1/60", "0.3", "2s", "1/3200"};
  EXPECT_EQ(match_shutter(sh, 1.0 / 60), "1/60");
  EXPECT_EQ(match_shutter(sh, 2.0), "2s");
  EXPECT_EQ(match_shutter(sh, 1.0 / 3000), "1/3200");  // within 1/6 stop
  EXPECT_FALSE(match_shutter(sh, 1.0 / 30).has_value());
  EXPECT_FALSE(match_shutter(sh, 0).has_value());
  std::vector<std::string> ap{"f/2.8", "f/5.6", "F8", "11.0"};
  EXPECT_EQ(match_aperture(ap, 5.6), "f/5.6");
  EXPECT_EQ(match_aperture(ap, 8), "F8");
  EXPECT_EQ(match_aperture(ap, 11), "11.0");
  EXPECT_FALSE(match_aperture(ap, 4).has_value());
  std::vector<std::string> iso{"Auto", "ISO 100", "200"};
  EXPECT_EQ(match_iso(iso, 100), "ISO 100");
  EXPECT_EQ(match_iso(iso, 200), "200");
  EXPECT_FALSE(match_iso(iso, 20).has_value());
}

TEST(Gphoto2, OptionsParseAndReject) {
  auto ok = parse_gphoto2_options({{"backend", "gphoto2"}, {"port", "usb:001,004"}, {"still_size", {1024, 680}}}, "camera");
  ASSERT_TRUE(ok.ok()) << ok.message();
  EXPECT_EQ(ok->still_width, 1024);
  auto bad_port = parse_gphoto2_options({{"port", "/dev/ttyS0"}}, "camera");
  ASSERT_FALSE(bad_port.ok());
  EXPECT_NE(bad_port.message().find("camera.port"), std::string::npos);
  auto unknown = parse_gphoto2_options({{"aperture", 8}}, "camera");
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.message().find("unknown field 'aperture'"), std::string::npos) << unknown.message();
}

TEST(Gphoto2, PtpipPortsNameBothConnectionsAndTheGenericDriver) {
  // libgphoto2 2.5.30 opens the event connection on 15740 unless it is named.
  auto plain = parse_gphoto2_options({{"port", "ptpip:192.168.1.20"}}, "camera");
  ASSERT_TRUE(plain.ok()) << plain.message();
  EXPECT_EQ(plain->port, "ptpip:192.168.1.20:15740:15740");
  EXPECT_EQ(plain->model, "PTP/IP Camera");
  auto with_port = parse_gphoto2_options({{"port", "ptpip:127.0.0.1:5555"}, {"model", "Nikon DSLR (WLAN)"}}, "camera");
  ASSERT_TRUE(with_port.ok()) << with_port.message();
  EXPECT_EQ(with_port->port, "ptpip:127.0.0.1:5555:5555");
  EXPECT_EQ(with_port->model, "Nikon DSLR (WLAN)");
  auto both = parse_gphoto2_options({{"port", "ptpip:10.0.0.2:15740:15741"}}, "camera");
  ASSERT_TRUE(both.ok()) << both.message();
  EXPECT_EQ(both->port, "ptpip:10.0.0.2:15740:15741");
  EXPECT_TRUE(is_network_port(both->port));
  EXPECT_FALSE(is_network_port("usb:001,004"));
  for (const char* bad : {"ptpip:", "ptpip:camera.local", "ptpip:10.0.0.256", "ptpip:10.0.0.2:0", "ptpip:10.0.0.2:x",
                          "ptpip:10.0.0.2:1:2:3"}) {
    auto r = parse_gphoto2_options({{"port", bad}}, "camera");
    ASSERT_FALSE(r.ok()) << bad;
    EXPECT_NE(r.message().find("is not a PTP/IP port"), std::string::npos) << r.message();
  }
}

}  // namespace
}  // namespace veneerd::hw
