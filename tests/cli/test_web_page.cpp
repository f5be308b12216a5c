// Issue 50 through the real binary and a real browser: `veneer transfer --web`
// on the demo pair (bull <- orange, 1024x680) writes a folder whose page,
// opened from file:// in Debian's headless Chromium with the network off and
// the light set through its URL (index.html#light=x,y), shows what `veneer
// relight` draws from the transfer's repainted photos at that light -- at two
// captured lamps and one between them, through WebGL and through the 2D
// canvas -- and does not when its planes are flipped upside down or its
// light's y is mirrored. Skipped, saying so, where no Chromium is installed
// (`make test` installs it: tools/debian-packages-test.txt).
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

namespace fs = std::filesystem;

namespace {

int run(const std::string& args) {
  const std::string cmd = VENEER_BIN_DIR "/veneer " + args + " >/dev/null 2>&1";
  const int status = std::system(cmd.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string slurp(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// The first of Debian's and others' names for Chromium on PATH, or "".
std::string find_chromium() {
  for (const char* name : {"chromium", "chromium-browser", "google-chrome", "google-chrome-stable"}) {
    const std::string probe = std::string("command -v ") + name + " >/dev/null 2>&1";
    if (std::system(probe.c_str()) == 0) return name;
  }
  return "";
}

// How the browser runs with the network off: in a network namespace of its
// own (`unshare --net` as root, `unshare -rn` where user namespaces are
// allowed), else only with flags that send every host name nowhere and every
// connection to a dead proxy.
std::string network_off_prefix(std::string& how) {
  if (std::system("unshare --net true >/dev/null 2>&1") == 0) {
    how = "unshare --net (no network interface but loopback, down)";
    return "unshare --net ";
  }
  if (std::system("unshare -rn true >/dev/null 2>&1") == 0) {
    how = "unshare -rn (a user and network namespace of its own)";
    return "unshare -rn ";
  }
  how = "no namespace could be made: host names resolve nowhere and connections go to a dead proxy (flags)";
  return "";
}

// Chromium headless runs, queued and then run side by side (each with a profile of its own).
struct Browser {
  std::string exe, prefix;
  fs::path dir;
  std::vector<std::string> queued;
  // a file:// page with the network off, software WebGL (SwiftShader), 1:1 pixels
  std::string command(const std::string& url, const std::string& what) {
    const fs::path profile = dir / ("profile_" + std::to_string(queued.size()));
    return prefix + exe + " --headless --no-sandbox --disable-gpu-sandbox --enable-unsafe-swiftshader --use-angle=swiftshader"
           " --no-first-run --no-default-browser-check --disable-extensions --disable-background-networking"
           " --host-resolver-rules='MAP * ~NOTFOUND' --proxy-server='socks5://127.0.0.1:9'"
           " --hide-scrollbars --force-device-scale-factor=1 --virtual-time-budget=8000"
           " --user-data-dir=" + profile.string() + " " + what + " '" + url + "'";
  }
  void screenshot(const std::string& url, const fs::path& png, cv::Size window) {
    queued.push_back(command(url, "--window-size=" + std::to_string(window.width) + "," + std::to_string(window.height) +
                                      " --screenshot=" + png.string()) + " >/dev/null 2>&1");
  }
  void dom(const std::string& url, const fs::path& out) { queued.push_back(command(url, "--dump-dom") + " >" + out.string() + " 2>/dev/null"); }
  void run_all() {
    std::string script = "(";
    for (const std::string& c : queued) script += " " + c + " &";
    script += " wait )";
    std::system(script.c_str());
    queued.clear();
  }
};

// Mean |a - b| over every pixel and colour, 8-bit levels (a screenshot may carry alpha).
double mean_levels(const fs::path& a_file, const fs::path& b_file) {
  const cv::Mat a = cv::imread(a_file.string(), cv::IMREAD_COLOR), b = cv::imread(b_file.string(), cv::IMREAD_COLOR);
  if (a.empty() || b.empty() || a.size() != b.size()) return 1e9;
  cv::Mat d;
  cv::absdiff(a, b, d);
  const cv::Scalar m = cv::mean(d);
  return (m[0] + m[1] + m[2]) / 3;
}

std::string base64_decode(const std::string& s) {
  std::string out;
  int bits = 0, value = 0;
  for (char c : s) {
    int v;
    if (c >= 'A' && c <= 'Z') v = c - 'A';
    else if (c >= 'a' && c <= 'z') v = c - 'a' + 26;
    else if (c >= '0' && c <= '9') v = c - '0' + 52;
    else if (c == '+') v = 62;
    else if (c == '/') v = 63;
    else continue;
    value = value << 6 | v;
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out += static_cast<char>(value >> bits & 0xff);
    }
  }
  return out;
}

std::string base64_encode(const std::string& bytes) {
  static const char* t = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  int bits = 0, value = 0;
  for (unsigned char c : bytes) {
    value = value << 8 | c;
    bits += 8;
    while (bits >= 6) {
      bits -= 6;
      out += t[value >> bits & 63];
    }
  }
  if (bits > 0) out += t[value << (6 - bits) & 63];
  while (out.size() % 4) out += '=';
  return out;
}

// A copy of the page whose planes are upside down (look.js's data: URLs decoded, flipped, encoded again).
void write_flipped_copy(const fs::path& page, const fs::path& copy) {
  fs::remove_all(copy);
  fs::copy(page, copy);
  const std::string js = slurp(page / "look.js");
  const std::string key = "window.VENEER_LOOK = ";
  const size_t at = js.find(key);
  ASSERT_NE(at, std::string::npos);
  const size_t end = js.rfind(';');
  auto look = nlohmann::json::parse(js.substr(at + key.size(), end - at - key.size()));
  for (auto& url : look["planes"]) {
    const std::string s = url.get<std::string>();
    const std::string b = base64_decode(s.substr(s.find(',') + 1));
    cv::Mat plane = cv::imdecode(std::vector<uchar>(b.begin(), b.end()), cv::IMREAD_COLOR);
    ASSERT_FALSE(plane.empty());
    cv::flip(plane, plane, 0);
    std::vector<uchar> jpg;
    cv::imencode(".jpg", plane, jpg, {cv::IMWRITE_JPEG_QUALITY, 95});
    url = "data:image/jpeg;base64," + base64_encode(std::string(jpg.begin(), jpg.end()));
  }
  std::ofstream(copy / "look.js") << key << look.dump() << ";\n";
}

uintmax_t folder_bytes(const fs::path& dir) {
  uintmax_t n = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) n += e.file_size();
  return n;
}

TEST(WebPage, InHeadlessChromiumTheLightFromTheUrlMatchesVeneersRelight) {
  const std::string exe = find_chromium();
  if (exe.empty()) GTEST_SKIP() << "no Chromium on PATH (chromium, chromium-browser, google-chrome): the web page is "
                                   "not tested in a browser; `make test` installs Debian's (tools/debian-packages-test.txt)";
  const fs::path dir = fs::temp_directory_path() / ("veneer-web-page-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  // the demo pair: the bull painted in the orange's material, 1024x680, the rig's 7 lamps
  const std::string sims = "( " VENEER_BIN_DIR "/veneer simulate --scene bull --role destination --out " + (dir / "dst").string() +
                           " >/dev/null & " VENEER_BIN_DIR "/veneer simulate --scene orange --role source --out " +
                           (dir / "src").string() + " >/dev/null & wait )";
  ASSERT_EQ(std::system(sims.c_str()), 0);
  ASSERT_TRUE(fs::exists(dir / "dst" / "set.json") && fs::exists(dir / "src" / "set.json"));
  const fs::path web = dir / "web", transfer = dir / "transfer";
  ASSERT_EQ(run("transfer --no-cache --web " + web.string() + " --out " + transfer.string() + " --dst " +
                (dir / "dst").string() + " --src " + (dir / "src").string()),
            0);
  for (const char* f : {"index.html", "look.js", "info.json", "still.jpg", "plane_0.jpg", "plane_3.jpg"})
    EXPECT_TRUE(fs::exists(web / f)) << f;
  const uintmax_t bytes = folder_bytes(web);
  std::printf("web page folder: %.2f MB\n", bytes / 1e6);
  EXPECT_LE(bytes, 5'000'000u) << "the demo pair's page must stay within 5 MB";
  // nothing on the page is fetched from the network: no URL with a scheme but data: in what it loads
  for (const char* f : {"index.html", "look.js"}) {
    const std::string text = slurp(web / f);
    EXPECT_EQ(text.find("http://"), std::string::npos) << f;
    EXPECT_EQ(text.find("https://"), std::string::npos) << f;
  }
  const std::string html = slurp(web / "index.html");
  EXPECT_NE(html.find(">bull<"), std::string::npos) << "the object's name";
  EXPECT_NE(html.find(">orange<"), std::string::npos) << "the source material's name";

  // the lights: two captured lamps (the destination's lamps 0 and 1) and one between them
  const auto set = nlohmann::json::parse(slurp(dir / "dst" / "set.json"));
  std::vector<cv::Vec2d> lights;
  cv::Vec3d sum(0, 0, 0);
  for (int i : {0, 1}) {
    const auto& d = set["lights"][i]["direction"];
    const cv::Vec3d v(d[0].get<double>(), d[1].get<double>(), d[2].get<double>());
    lights.emplace_back(v[0], v[1]);
    sum += v / cv::norm(v);
  }
  sum /= cv::norm(sum);
  lights.emplace_back(sum[0], sum[1]);

  Browser browser;
  browser.exe = exe;
  std::string how;
  browser.prefix = network_off_prefix(how);
  browser.dir = dir;
  std::printf("browser: %s, network off by %s\n", exe.c_str(), how.c_str());
  const cv::Size window(1024, 680);
  const std::string page = "file://" + (web / "index.html").string();
  auto at = [](cv::Vec2d l) {
    char s[64];
    std::snprintf(s, sizeof s, "%.4f,%.4f", l[0], l[1]);
    return std::string(s);
  };

  // every page at once: the three lights (WebGL where the browser has it), the 2D canvas between the
  // lamps, lamp 0 with the light's y mirrored, lamp 0 with the planes upside down, and what drew
  write_flipped_copy(web, dir / "flipped");
  for (size_t i = 0; i < lights.size(); ++i)
    browser.screenshot(page + "#light=" + at(lights[i]) + "&bare", dir / ("page_" + std::to_string(i) + ".png"), window);
  browser.screenshot(page + "#light=" + at(lights[2]) + "&bare&renderer=2d", dir / "page_2d.png", window);
  browser.screenshot(page + "#light=" + at({lights[0][0], -lights[0][1]}) + "&bare", dir / "page_mirrored.png", window);
  browser.screenshot("file://" + (dir / "flipped" / "index.html").string() + "#light=" + at(lights[0]) + "&bare",
                     dir / "page_flipped.png", window);
  browser.dom(page + "#light=" + at(lights[0]) + "&bare", dir / "dom.html");
  std::string relights = "(";
  for (size_t i = 0; i < lights.size(); ++i)
    relights += " " VENEER_BIN_DIR "/veneer relight --transfer " + transfer.string() + " --dst " + (dir / "dst").string() +
                " --light=" + at(lights[i]) + " --out " + (dir / ("relight_" + std::to_string(i) + ".png")).string() +
                " >/dev/null 2>&1 &";
  relights += " wait )";
  ASSERT_EQ(std::system(relights.c_str()), 0);
  browser.run_all();

  const std::string dom = slurp(dir / "dom.html");
  const bool webgl = dom.find("data-renderer=\"webgl\"") != std::string::npos;
  EXPECT_TRUE(webgl || dom.find("data-renderer=\"2d\"") != std::string::npos)
      << "the page did not draw (its still stays): " << dom.substr(0, 400);
  std::printf("the page drew through %s\n", webgl ? "WebGL" : "the 2D canvas (no WebGL in this browser)");
  for (size_t i = 0; i < lights.size(); ++i) {
    const double levels = mean_levels(dir / ("page_" + std::to_string(i) + ".png"), dir / ("relight_" + std::to_string(i) + ".png"));
    std::printf("light %s (%s): page against veneer relight %.2f levels mean\n", at(lights[i]).c_str(),
                i < 2 ? ("lamp " + std::to_string(i)).c_str() : "between lamps 0 and 1", levels);
    EXPECT_LE(levels, 3.0) << "light " << at(lights[i]);
  }
  const double canvas_levels = mean_levels(dir / "page_2d.png", dir / "relight_2.png");
  std::printf("2D canvas between the lamps: %.2f levels mean\n", canvas_levels);
  EXPECT_LE(canvas_levels, 3.0);
  // measured (demo pair, WebGL through SwiftShader and the 2D canvas alike): 2.06, 2.03, 2.00 levels -- JPEG's
  // loss of the photos' sensor noise (after a 7x7 box blur 0.3); what must fail: the light's y mirrored and
  // the planes upside down, 13.3 and 16.0 levels
  const double mirrored_levels = mean_levels(dir / "page_mirrored.png", dir / "relight_0.png");
  const double flipped_levels = mean_levels(dir / "page_flipped.png", dir / "relight_0.png");
  std::printf("lamp 0 with the light's y mirrored: %.2f levels mean; with the planes upside down: %.2f\n",
              mirrored_levels, flipped_levels);
  EXPECT_GT(mirrored_levels, 6.0);
  EXPECT_GT(flipped_levels, 6.0);
  if (std::getenv("VENEER_KEEP_WEB_PAGE")) {
    std::printf("kept %s\n", dir.c_str());
    return;
  }
  fs::remove_all(dir);
}

}  // namespace
