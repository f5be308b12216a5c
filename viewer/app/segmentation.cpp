#include "segmentation.hpp"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "qt_convert.hpp"
#include "veneer/ps/segmentation.hpp"

namespace veneer::app {

SegmentationTool::SegmentationTool(Session& session, QObject* parent) : QObject(parent), session_(session) {}

// The hand mask starts from what the automatic segmentation found.
bool SegmentationTool::startHandMask(LoadedSet& s) {
  if (!s.hand_mask.empty()) return true;
  if (s.normals && !s.normals->mask.empty()) {
    s.hand_mask = s.normals->mask.clone();
    return true;
  }
  auto seg = veneer::ps::segment(s.set);
  if (!seg) {
    session_.message(tr("segmentation of %1: %2").arg(s.folder, qs(seg.message())), true);
    return false;
  }
  s.hand_mask = seg->mask.clone();
  return true;
}

void SegmentationTool::setHandRect(veneer::io::Role role, const QRect& rect) {
  auto s = session_.setFor(role);
  if (!s || rect.isEmpty()) return;
  const cv::Rect r = cv::Rect(rect.x(), rect.y(), rect.width(), rect.height()) & cv::Rect(cv::Point(), s->set.size);
  if (r.empty()) return session_.message(tr("the rectangle is outside the picture"), true);
  if (!startHandMask(*s)) return;
  cv::Mat keep(s->hand_mask.size(), CV_8UC1, cv::Scalar(0));
  keep(r).setTo(255);
  cv::bitwise_and(s->hand_mask, keep, s->hand_mask);
  changed(role);
}

void SegmentationTool::brushHandMask(veneer::io::Role role, QPoint pixel, bool add, int radius) {
  auto s = session_.setFor(role);
  if (!s) return;
  if (!startHandMask(*s)) return;
  if (radius <= 0) radius = std::max(3, s->set.size.width / 60);
  cv::circle(s->hand_mask, cv::Point(pixel.x(), pixel.y()), radius, cv::Scalar(add ? 255 : 0), cv::FILLED);
  changed(role);
}

void SegmentationTool::clearHandMask(veneer::io::Role role) {
  auto s = session_.setFor(role);
  if (!s || s->hand_mask.empty()) return;
  s->hand_mask.release();
  changed(role);
}

void SegmentationTool::restoreHandMask(veneer::io::Role role, const cv::Mat& mask) {
  auto s = session_.setFor(role);
  if (!s || mask.empty() || mask.size() != s->set.size) return;
  s->hand_mask = mask;
  changed(role);
}

QStringList SegmentationTool::exportMasksTo(const QString& dir) {
  QStringList written;
  for (auto [set, name] : {std::pair{session_.dst, "dst-mask.png"}, std::pair{session_.src, "src-mask.png"}}) {
    if (!set || set->hand_mask.empty()) continue;
    const QString file = dir + "/" + name;
    if (!cv::imwrite(file.toStdString(), set->hand_mask)) {
      session_.message(tr("cannot write %1").arg(file), true);
      return written;
    }
    written << file;
  }
  session_.message(written.isEmpty()
                       ? tr("no mask drawn by hand to export")
                       : tr("masks written: %1 (veneer transfer --dst-mask / --src-mask)").arg(written.join(", ")),
                   written.isEmpty());
  return written;
}

void SegmentationTool::changed(veneer::io::Role role) {
  auto s = session_.setFor(role);
  ++s->hand_version;
  std::vector<QPolygonF> outline;
  if (!s->hand_mask.empty()) {
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(s->hand_mask, contours, cv::RETR_LIST, cv::CHAIN_APPROX_SIMPLE);
    for (const auto& c : contours) {
      QPolygonF p;
      for (const auto& q : c) p << QPointF(q.x, q.y);
      outline.push_back(p);
    }
  }
  const auto& dst = session_.dst;
  const auto& src = session_.src;
  emit maskChanged(role, outline,
                   tr("by hand: destination %1, source %2 (shift+drag: rectangle; ctrl+drag: add; alt+drag: "
                      "remove)")
                       .arg(dst && !dst->hand_mask.empty() ? tr("yes") : tr("no"))
                       .arg(src && !src->hand_mask.empty() ? tr("yes") : tr("no")));
}

}  // namespace veneer::app
