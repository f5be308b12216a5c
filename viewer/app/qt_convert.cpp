#include "qt_convert.hpp"

#include <opencv2/imgproc.hpp>

#include "veneer/io/image_io.hpp"

namespace veneer::app {

QImage to_qimage(const cv::Mat& picture) {
  if (picture.empty()) return {};
  cv::Mat bgr;
  if (picture.depth() == CV_32F) {
    bgr = picture.channels() == 3 ? io::tonemap_picture(picture) : cv::Mat();
    if (bgr.empty()) {
      cv::Mat g;
      picture.convertTo(g, CV_8U, 255.0);
      cv::cvtColor(g, bgr, cv::COLOR_GRAY2BGR);
    }
  } else if (picture.channels() == 1) {
    cv::cvtColor(picture, bgr, cv::COLOR_GRAY2BGR);
  } else {
    bgr = picture;
  }
  // Format_RGB32 (0xffRRGGBB: bytes B, G, R, 255 in memory) is what the
  // raster painter scales fastest; RGB888 was converted on every paint.
  // The QImage owns the converted buffer: no second copy.
  auto* bgra = new cv::Mat;
  cv::cvtColor(bgr, *bgra, cv::COLOR_BGR2BGRA);
  return QImage(
      bgra->data, bgra->cols, bgra->rows, static_cast<qsizetype>(bgra->step), QImage::Format_RGB32,
      [](void* m) { delete static_cast<cv::Mat*>(m); }, bgra);
}

cv::Mat to_mat(const QImage& image) {
  QImage rgb = image.convertToFormat(QImage::Format_RGB888);
  cv::Mat view(rgb.height(), rgb.width(), CV_8UC3, const_cast<uchar*>(rgb.constBits()),
               static_cast<size_t>(rgb.bytesPerLine()));
  cv::Mat bgr;
  cv::cvtColor(view, bgr, cv::COLOR_RGB2BGR);
  return bgr;
}

QString qs(const std::string& s) { return QString::fromStdString(s); }

}  // namespace veneer::app
