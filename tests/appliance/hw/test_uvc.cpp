// The UVC back-end without a webcam: open fails with a clear message.
#include <gtest/gtest.h>

#include "veneerd/hw/uvc.hpp"

namespace veneerd::hw {
namespace {

TEST(Uvc, NoDeviceGivesClearMessage) {
  UvcOptions o;
  o.device = "/dev/video-veneer-missing";
  UvcCamera cam(o);
  auto s = cam.open();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("/dev/video-veneer-missing does not exist"), std::string::npos) << s.message();
  EXPECT_FALSE(cam.connected());
  auto still = cam.capture();
  ASSERT_FALSE(still.ok());
  EXPECT_FALSE(cam.preview().ok());
}

TEST(Uvc, NonCaptureDeviceRefused) {
  UvcOptions o;
  o.device = "/dev/null";  // exists, but is no V4L2 device
  UvcCamera cam(o);
  auto s = cam.open();
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("cannot open /dev/null"), std::string::npos) << s.message();
}

TEST(Uvc, OptionsParse) {
  auto o = parse_uvc_options({{"backend", "uvc"}, {"device", 2}, {"width", 640}}, "camera");
  ASSERT_TRUE(o.ok()) << o.message();
  EXPECT_EQ(o->device, "2");
  EXPECT_EQ(o->width, 640);
  auto bad = parse_uvc_options({{"width", 5}}, "camera");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("camera.width"), std::string::npos) << bad.message();
}

}  // namespace
}  // namespace veneerd::hw
