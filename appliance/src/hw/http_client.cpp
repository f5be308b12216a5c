// libcurl multi interface behind HttpClient; no CURL type leaves this file.
#include "http_client.hpp"

#include <curl/curl.h>

#include <map>
#include <mutex>

namespace veneerd::hw::detail {

namespace {

std::once_flag curl_once;

constexpr size_t kMaxAnswerBytes = 4u << 20;  // a Hue bridge's answers are small; refuse floods

size_t collect(char* data, size_t size, size_t count, void* user) {
  auto* out = static_cast<std::string*>(user);
  if (out->size() + size * count > kMaxAnswerBytes) return 0;  // aborts the transfer (write error)
  out->append(data, size * count);
  return size * count;
}

struct EasyDeleter {
  void operator()(CURL* e) const { curl_easy_cleanup(e); }
};
struct SlistDeleter {
  void operator()(curl_slist* s) const { curl_slist_free_all(s); }
};
struct MultiDeleter {
  void operator()(CURLM* m) const { curl_multi_cleanup(m); }
};

}  // namespace

struct HttpClient::Impl {
  // Owned handles. Easy handles are taken out of the multi handle (cancel_all,
  // in the destructor) before either is freed.
  std::unique_ptr<CURLM, MultiDeleter> multi;
  struct Transfer {
    int ticket = 0;
    std::unique_ptr<CURL, EasyDeleter> easy;
    std::unique_ptr<curl_slist, SlistDeleter> headers;
    std::string request_body;
    std::string response_body;
  };
  std::map<CURL*, Transfer> running;
  std::vector<std::unique_ptr<CURL, EasyDeleter>> idle;  // reused handles keep their connection cache small
  std::vector<std::pair<int, HttpResult>> failed;  // requests libcurl could not even start
  int next_ticket = 1;

  Impl() {
    std::call_once(curl_once, [] { curl_global_init(CURL_GLOBAL_DEFAULT); });
    multi.reset(curl_multi_init());
    if (!multi) return;
    curl_multi_setopt(multi.get(), CURLMOPT_MAX_HOST_CONNECTIONS, 3L);
    curl_multi_setopt(multi.get(), CURLMOPT_MAXCONNECTS, 8L);
  }
  ~Impl() { cancel_all(); }

  void cancel_all() {
    for (auto& [easy, t] : running) curl_multi_remove_handle(multi.get(), easy);
    running.clear();
    failed.clear();
  }

  std::unique_ptr<CURL, EasyDeleter> take_easy() {
    if (!idle.empty()) {
      auto e = std::move(idle.back());
      idle.pop_back();
      curl_easy_reset(e.get());
      return e;
    }
    return std::unique_ptr<CURL, EasyDeleter>(curl_easy_init());
  }

  int start(const HttpCall& call) {
    Transfer t;
    t.ticket = next_ticket++;
    t.easy = multi ? take_easy() : nullptr;
    if (!t.easy) {
      HttpResult r;
      r.error = "libcurl could not create a handle";
      failed.emplace_back(t.ticket, std::move(r));
      return t.ticket;
    }
    t.request_body = call.body;
    CURL* e = t.easy.get();
    curl_easy_setopt(e, CURLOPT_URL, call.url.c_str());
    curl_easy_setopt(e, CURLOPT_NOSIGNAL, 1L);
    curl_easy_setopt(e, CURLOPT_TIMEOUT_MS, std::max(1L, call.timeout_ms));
    curl_easy_setopt(e, CURLOPT_CONNECTTIMEOUT_MS, std::max(1L, call.timeout_ms));
    curl_easy_setopt(e, CURLOPT_TCP_NODELAY, 1L);
    curl_easy_setopt(e, CURLOPT_PROTOCOLS_STR, "http,https");
    curl_easy_setopt(e, CURLOPT_WRITEFUNCTION, collect);
    curl_easy_setopt(e, CURLOPT_MAXFILESIZE, static_cast<long>(kMaxAnswerBytes));
    curl_slist* h = curl_slist_append(nullptr, "Content-Type: application/json");
    h = curl_slist_append(h, "Expect:");  // no 100-continue round trip
    t.headers.reset(h);
    curl_easy_setopt(e, CURLOPT_HTTPHEADER, h);
    if (call.method == "GET") {
      curl_easy_setopt(e, CURLOPT_HTTPGET, 1L);
    } else {
      curl_easy_setopt(e, CURLOPT_CUSTOMREQUEST, call.method.c_str());
      curl_easy_setopt(e, CURLOPT_POSTFIELDS, t.request_body.c_str());
      curl_easy_setopt(e, CURLOPT_POSTFIELDSIZE, static_cast<long>(t.request_body.size()));
    }
    int ticket = t.ticket;
    auto [it, inserted] = running.emplace(e, std::move(t));
    // The map node is stable: the write target is its own response_body.
    curl_easy_setopt(e, CURLOPT_WRITEDATA, &it->second.response_body);
    curl_multi_add_handle(multi.get(), e);
    return ticket;
  }

  std::vector<std::pair<int, HttpResult>> poll(std::chrono::milliseconds timeout) {
    std::vector<std::pair<int, HttpResult>> done;
    if (!failed.empty()) {
      done.swap(failed);
      return done;
    }
    if (!multi) return done;
    int still = 0;
    curl_multi_perform(multi.get(), &still);
    done = collect_done();
    if (!done.empty() || running.empty()) return done;
    int numfds = 0;
    curl_multi_poll(multi.get(), nullptr, 0, static_cast<int>(std::max<long long>(0, timeout.count())), &numfds);
    curl_multi_perform(multi.get(), &still);
    return collect_done();
  }

  std::vector<std::pair<int, HttpResult>> collect_done() {
    std::vector<std::pair<int, HttpResult>> done;
    int left = 0;
    while (CURLMsg* msg = curl_multi_info_read(multi.get(), &left)) {
      if (msg->msg != CURLMSG_DONE) continue;
      CURL* e = msg->easy_handle;
      CURLcode code = msg->data.result;
      auto it = running.find(e);
      if (it == running.end()) continue;
      HttpResult r;
      if (code == CURLE_OK) {
        r.transport_ok = true;
        curl_easy_getinfo(e, CURLINFO_RESPONSE_CODE, &r.status);
        r.body = std::move(it->second.response_body);
      } else {
        r.error = curl_easy_strerror(code);
      }
      int ticket = it->second.ticket;
      curl_multi_remove_handle(multi.get(), e);
      idle.push_back(std::move(it->second.easy));
      running.erase(it);
      done.emplace_back(ticket, std::move(r));
    }
    return done;
  }
};

HttpClient::HttpClient() : impl_(std::make_unique<Impl>()) {}
HttpClient::~HttpClient() = default;

int HttpClient::start(const HttpCall& call) { return impl_->start(call); }
std::vector<std::pair<int, HttpResult>> HttpClient::poll(std::chrono::milliseconds timeout) {
  return impl_->poll(timeout);
}
int HttpClient::active() const { return static_cast<int>(impl_->running.size() + impl_->failed.size()); }
void HttpClient::cancel_all() { impl_->cancel_all(); }

HttpResult HttpClient::perform(const HttpCall& call) {
  int ticket = start(call);
  for (;;) {
    for (auto& [t, r] : poll(std::chrono::milliseconds(50)))
      if (t == ticket) return std::move(r);
  }
}

}  // namespace veneerd::hw::detail
