#pragma once
// The edge between OpenCV pictures and Qt images (no algorithm, just copies).
#include <QImage>
#include <QMetaType>
#include <QString>

#include <opencv2/core.hpp>

#include "veneer/rig/client.hpp"

namespace veneer::app {

// 8-bit BGR / grey, or linear float BGR (tonemapped for display) → QImage
// (Format_RGB32, its own pixels).
QImage to_qimage(const cv::Mat& picture);
// QImage → 8-bit BGR.
cv::Mat to_mat(const QImage& image);
QString qs(const std::string& s);

}  // namespace veneer::app

Q_DECLARE_METATYPE(veneer::rig::Event)
Q_DECLARE_METATYPE(veneer::rig::RigStatus)
Q_DECLARE_METATYPE(veneer::rig::LiveFrame)
Q_DECLARE_METATYPE(std::vector<veneer::rig::SetSummary>)
