// core/Specular: RTI's specular enhancement against pixels computed by hand.
#include <gtest/gtest.h>

#include <cmath>

#include "veneer/repaint/specular.hpp"

using veneer::repaint::specular_enhancement;

// Four normals in a row under a light from (0.6, 0, 0.8):
//  0: (0, 0, 0)          outside the object: black.
//  1: (0, 0, 1)          n.l = 0.8; h = normalise(0.6, 0, 1.8) = (0.31623, 0, 0.94868),
//                        n.h = 0.94868, ^60 = 0.04239; 255 * (0.55 * 0.8 + 0.7 * 0.04239) = 119.8 -> 120.
//  2: h turned by acos(0.99) towards z (angle from z 0.32175 - 0.14153 = 0.18022 rad):
//                        n = (0.17924, 0, 0.98381); n.l = 0.89459; n.h = 0.99, ^60 = 0.54716;
//                        255 * (0.55 * 0.89459 + 0.7 * 0.54716) = 223.1 -> 223.
//  3: (-1, 0, 0)         faces away: n.l < 0, n.h < 0: 0.
TEST(Specular, PixelsAsComputedByHand) {
  cv::Mat normals(1, 4, CV_32FC3);
  normals.at<cv::Vec3f>(0, 0) = {0, 0, 0};
  normals.at<cv::Vec3f>(0, 1) = {0, 0, 1};
  const float a = 0.32175055f - std::acos(0.99f);
  normals.at<cv::Vec3f>(0, 2) = {std::sin(a), 0, std::cos(a)};
  normals.at<cv::Vec3f>(0, 3) = {-1, 0, 0};
  // not unit on purpose: the direction is normalised
  auto out = specular_enhancement(normals, cv::Vec3d(1.2, 0, 1.6));
  ASSERT_TRUE(out) << out.message();
  ASSERT_EQ(out->type(), CV_8UC3);
  ASSERT_EQ(out->size(), normals.size());
  const int want[] = {0, 120, 223, 0};
  for (int x = 0; x < 4; ++x) {
    const cv::Vec3b p = out->at<cv::Vec3b>(0, x);
    EXPECT_EQ(p[0], want[x]) << "pixel " << x;
    EXPECT_TRUE(p[0] == p[1] && p[1] == p[2]) << "grey at pixel " << x;
  }
  // a surface facing the light and the camera saturates at white
  cv::Mat facing(1, 1, CV_32FC3, cv::Scalar(0, 0, 1));
  auto white = specular_enhancement(facing, cv::Vec3d(0, 0, 1));
  ASSERT_TRUE(white);
  EXPECT_EQ(white->at<cv::Vec3b>(0, 0), cv::Vec3b(255, 255, 255));
  // the weights are the options': no highlight, diffuse 1 -> 255 * 0.8 = 204
  veneer::repaint::SpecularOptions matte;
  matte.diffuse = 1;
  matte.specular = 0;
  auto plain = specular_enhancement(normals, cv::Vec3d(0.6, 0, 0.8), matte);
  ASSERT_TRUE(plain);
  EXPECT_EQ(plain->at<cv::Vec3b>(0, 1)[0], 204);
}

TEST(Specular, BadInputIsNamed) {
  cv::Mat n(2, 2, CV_32FC3, cv::Scalar(0, 0, 1));
  auto wrong_type = specular_enhancement(cv::Mat(2, 2, CV_8UC3), cv::Vec3d(0, 0, 1));
  ASSERT_FALSE(wrong_type);
  EXPECT_NE(wrong_type.message().find("CV_32FC3"), std::string::npos) << wrong_type.message();
  auto zero = specular_enhancement(n, cv::Vec3d(0, 0, 0));
  ASSERT_FALSE(zero);
  EXPECT_NE(zero.message().find("direction"), std::string::npos) << zero.message();
  EXPECT_FALSE(specular_enhancement(cv::Mat(), cv::Vec3d(0, 0, 1)));
  veneer::repaint::SpecularOptions o;
  o.exponent = 0;
  auto bad = specular_enhancement(n, cv::Vec3d(0, 0, 1), o);
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.message().find("exponent"), std::string::npos) << bad.message();
}
