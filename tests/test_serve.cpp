//
// yscene serve's API, in process: a real server on an ephemeral port, real
// requests through cpp-httplib's client, real PNG frames decoded by
// OpenImageIO, and a saved scene rendered again by the command line.
//

#include <gtest/gtest.h>
#include <httplib.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <thread>
#include <yocto/yocto_hairgen.h>
#include <yocto/yocto_image.h>
#include <yocto/yocto_sceneio.h>
#include <yocto/yocto_serve.h>

#include "run_yscene.h"

using namespace yocto;
using json   = nlohmann::json;
namespace fs = std::filesystem;

// A folder of its own per test, removed after it.
struct serve_folder {
  fs::path path;
  serve_folder() {
    auto info = ::testing::UnitTest::GetInstance()->current_test_info();
    path      = fs::temp_directory_path() /
           ("yocto_serve_" + std::to_string(getpid()) + "_" + info->name());
    fs::remove_all(path);
    fs::create_directories(path / "out");
  }
  ~serve_folder() { fs::remove_all(path); }
};

// A small blond straight groom under the sky, served at 48 pixels, 64
// samples, on two threads, with a known token.
struct test_server {
  scene_server server = {};
  std::string  token  = "0123456789abcdef0123456789abcdef";
  std::string  scene  = "";
  explicit test_server(const serve_folder& folder, int samples = 64, bool aovs = false) {
    auto style    = hair_style_params{};
    style.strands = 600;
    auto hair     = hair_material{};
    hair.eumelanin = 0.3f;
    scene          = (folder.path / "scene" / "groom.json").string();
    fs::create_directories(folder.path / "scene");
    auto error = std::string{};
    EXPECT_TRUE(save_scene(scene, make_hair_scene(style, hair), error)) << error;
    auto settings             = render_session_params{};
    settings.scene            = scene;
    settings.samples_given    = true;
    settings.resolution_given = true;
    auto params       = trace_params{};
    params.samples    = samples;
    params.resolution = 48;
    params.threads    = 2;
    params.aovs       = aovs;
    auto session      = std::make_unique<render_session>();
    EXPECT_TRUE(load_render_session(*session, settings, params, error)) << error;
    EXPECT_TRUE(build_render_session(*session, error)) << error;
    auto serve       = serve_params{};
    serve.port       = 0;
    serve.token      = token;
    serve.output_dir = (folder.path / "out").string();
    EXPECT_TRUE(start_scene_server(server, std::move(session), serve, error)) << error;
  }
  ~test_server() { stop_scene_server(server); }
  httplib::Client client() const {
    auto client = httplib::Client("127.0.0.1", server.port);
    client.set_read_timeout(60);
    return client;
  }
  httplib::Headers headers() const { return {{"X-Token", token}}; }
  json get_state() const {
    auto result = client().Get("/api/state", headers());
    if (!result || result->status != 200) return json{};
    return json::parse(result->body);
  }
  httplib::Result post(const std::string& path, const std::string& body) const {
    return client().Post(path.c_str(), headers(), body, "application/json");
  }
  // Waits until a full frame of at least `samples` samples shows generation
  // `generation` or later; false after 60 s.
  bool wait_frame(int generation, int samples) const {
    auto start = std::chrono::steady_clock::now();
    while (std::chrono::steady_clock::now() - start < std::chrono::seconds(60)) {
      auto state = get_state();
      if (!state.is_null() && state["frame_generation"].get<int>() >= generation &&
          !state["preview"].get<bool>() && state["samples"].get<int>() >= samples)
        return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return false;
  }
  // The current frame decoded (sRGB PNG back to linear by load_image).
  texture_data get_frame(const fs::path& folder, const std::string& query = "") const {
    auto result = client().Get(("/api/frame.png?" + query).c_str(), headers());
    auto image  = texture_data{};
    if (!result || result->status != 200) return image;
    auto filename = (folder / "frame.png").string();
    std::ofstream(filename, std::ios::binary) << result->body;
    auto error = std::string{};
    load_image(filename, image, error);
    return image;
  }
};

static double mean_value(const texture_data& image) {
  auto sum = 0.0;
  for (auto& pixel : image.pixels) sum += (pixel.x + pixel.y + pixel.z) / 3;
  return image.pixels.empty() ? 0 : sum / image.pixels.size();
}

static double mean_difference(const texture_data& a, const texture_data& b) {
  if (a.pixels.size() != b.pixels.size() || a.pixels.empty()) return 1e30;
  auto sum = 0.0;
  for (size_t i = 0; i < a.pixels.size(); i++) {
    auto d = abs(a.pixels[i] - b.pixels[i]);
    sum += (d.x + d.y + d.z) / 3;
  }
  return sum / a.pixels.size();
}

TEST(serve, every_request_needs_the_token) {
  auto folder = serve_folder{};
  auto server = test_server{folder};
  auto client = server.client();
  for (auto path : {"/", "/serve.js", "/serve.css", "/api/state", "/api/frame.png"}) {
    auto none = client.Get(path);
    ASSERT_TRUE(none) << path;
    EXPECT_EQ(none->status, 403) << path;
    auto wrong = client.Get(path, httplib::Headers{{"X-Token", std::string(32, '0')}});
    EXPECT_EQ(wrong->status, 403) << path;
    auto shorter = client.Get((std::string(path) + "?token=0123").c_str());
    EXPECT_EQ(shorter->status, 403) << path;
    EXPECT_EQ(none->get_header_value("Access-Control-Allow-Origin"), "") << path;
  }
  auto edit = client.Post("/api/material", R"({"material":0,"parameter":"eumelanin","value":2})",
      "application/json");
  EXPECT_EQ(edit->status, 403);
  EXPECT_EQ(server.get_state()["generation"], 0);  // the edit without the token did nothing
  auto page = client.Get(("/?token=" + server.token).c_str());
  ASSERT_TRUE(page);
  EXPECT_EQ(page->status, 200);
  EXPECT_NE(page->get_header_value("Content-Type").find("text/html"), std::string::npos);
  EXPECT_EQ(client.Get("/api/state", server.headers())->status, 200);
  // No path from a request reaches the disk: anything else is 404.
  EXPECT_EQ(client.Get("/../../etc/passwd", server.headers())->status, 404);
  EXPECT_EQ(client.Get("/apps/serve/index.html", server.headers())->status, 404);
}

TEST(serve, bad_requests_are_answered_400_and_change_nothing) {
  auto folder = serve_folder{};
  auto server = test_server{folder};
  ASSERT_TRUE(server.wait_frame(0, 1));
  auto before = server.get_state();
  struct bad_request {
    std::string path, body, field;
  };
  auto long_body = R"({"material":0,"parameter":"eumelanin","value":1,"x":")" +
                   std::string(5000, 'a') + "\"}";
  auto requests = std::vector<bad_request>{
      {"/api/material", R"({"material":"nope","parameter":"eumelanin","value":1})", "material"},
      {"/api/material", R"({"material":7,"parameter":"eumelanin","value":1})", "material"},
      {"/api/material", R"({"material":0,"parameter":"shine","value":1})", "parameter"},
      {"/api/material", R"({"material":0,"parameter":"eumelanin","value":-1})", "value"},
      {"/api/material", R"({"material":0,"parameter":"beta_m","value":1.5})", "value"},
      {"/api/material", R"({"material":0,"parameter":"color","value":[0.5,0.5]})", "value"},
      {"/api/material", R"({"material":0,"parameter":"color","value":[0.5,0.5,2]})", "value"},
      {"/api/material", R"({"material":0,"parameter":"eumelanin","value":"dark"})", "value"},
      {"/api/material", R"({"material":0,"parameter":"eumelanin"})", "value"},
      {"/api/material", R"({"material":0,"parameter":"eumelanin","value":1,"extra":1})",
          "extra"},
      {"/api/material", R"({"material":0,"parameter":"eumelanin","value":NaN})", ""},
      {"/api/material", R"({"material":0,"parameter":"eumelanin","value":1e999})", ""},
      {"/api/material", R"({"material":0,"parameter":)", ""},
      {"/api/material", R"([1,2,3])", ""},
      {"/api/material", long_body, "body"},
      {"/api/environment", R"({"environment":0,"strength":-2})", "strength"},
      {"/api/environment", R"({"environment":3,"strength":2})", "environment"},
      {"/api/light", R"({"light":0,"strength":2})", "light"},
      {"/api/camera", R"({"camera":"nowhere"})", "camera"},
      {"/api/camera", R"({"zoom":0})", "zoom"},
      {"/api/camera", R"({"orbit":[1]})", "orbit"},
      {"/api/camera", R"({"pan":[1e30,0]})", "pan"},
      {"/api/save", R"({"exposure":"bright"})", "exposure"},
  };
  for (auto& request : requests) {
    auto result = server.post(request.path, request.body);
    ASSERT_TRUE(result) << request.body.substr(0, 80);
    EXPECT_EQ(result->status, 400) << request.body.substr(0, 80);
    auto body = json::parse(result->body, nullptr, false);
    ASSERT_TRUE(body.is_object()) << result->body;
    EXPECT_TRUE(body.contains("error")) << result->body;
    if (!request.field.empty()) EXPECT_EQ(body.value("field", ""), request.field) << result->body;
  }
  for (auto query : {"layer=albedo", "exposure=nan", "exposure=1e9", "exposure=2x", "view=log"}) {
    auto result = server.client().Get(("/api/frame.png?" + std::string(query)).c_str(),
        server.headers());
    EXPECT_EQ(result->status, 400) << query;
  }
  for (auto query : {"after=", "after=x", "after=-1", "after=1e3", "after=99999999999"}) {
    auto result = server.client().Get(("/api/state?" + std::string(query)).c_str(),
        server.headers());
    EXPECT_EQ(result->status, 400) << query;
    EXPECT_EQ(json::parse(result->body, nullptr, false).value("field", ""), "after") << query;
  }
  auto after = server.get_state();
  EXPECT_EQ(after["generation"], before["generation"]);
  EXPECT_EQ(after["materials"], before["materials"]);
  EXPECT_EQ(after["environments"], before["environments"]);
  EXPECT_EQ(fs::is_empty(folder.path / "out"), true);  // the bad save wrote nothing
}

TEST(serve, a_parameter_change_shows_in_the_next_frames) {
  auto folder = serve_folder{};
  auto server = test_server{folder};
  ASSERT_TRUE(server.wait_frame(0, 16));
  auto blond = server.get_frame(folder.path);
  // The noise of the blond frames: their 16-sample frame against the next
  // one of the same generation.
  ASSERT_TRUE(server.wait_frame(0, 32));
  auto blond_later = server.get_frame(folder.path);
  auto noise       = mean_difference(blond, blond_later);
  auto edit = server.post("/api/material", R"({"material":"hair","parameter":"eumelanin","value":8})");
  ASSERT_TRUE(edit);
  ASSERT_EQ(edit->status, 200) << edit->body;
  auto generation = json::parse(edit->body)["generation"].get<int>();
  EXPECT_EQ(generation, 1);
  ASSERT_TRUE(server.wait_frame(generation, 16));
  auto dark  = server.get_frame(folder.path);
  auto state = server.get_state();
  EXPECT_EQ(state["materials"][0]["parameters"][2]["name"], "eumelanin");
  EXPECT_FLOAT_EQ(state["materials"][0]["parameters"][2]["value"].get<float>(), 8);
  // Eumelanin 8 is black hair: darker (the sky around it stays), and each
  // pixel by far more than the noise.
  EXPECT_LT(mean_value(dark), mean_value(blond) - 5 * noise);
  EXPECT_GT(mean_difference(blond, dark), 5 * noise);
  // The exposure is the client's: +1 stop doubles what the PNG shows (below
  // its clipping), and the render does not restart.
  auto brighter = server.get_frame(folder.path, "exposure=1");
  ASSERT_EQ(brighter.pixels.size(), dark.pixels.size());
  auto sum_dark = 0.0, sum_bright = 0.0;
  for (size_t i = 0; i < dark.pixels.size(); i++) {
    if (max_component(brighter.pixels[i]) > 0.9f || max_component(dark.pixels[i]) < 0.05f)
      continue;
    sum_dark += dark.pixels[i].x + dark.pixels[i].y + dark.pixels[i].z;
    sum_bright += brighter.pixels[i].x + brighter.pixels[i].y + brighter.pixels[i].z;
  }
  ASSERT_GT(sum_dark, 0);
  EXPECT_NEAR(sum_bright / sum_dark, 2, 0.1);
  EXPECT_EQ(server.get_state()["generation"], generation);
}

TEST(serve, a_long_poll_answers_with_the_next_frame) {
  auto folder = serve_folder{};
  auto server = test_server{folder, 1 << 20};
  ASSERT_TRUE(server.wait_frame(0, 1));
  auto frame = server.get_state()["frame"].get<int>();
  auto next  = json{};
  // Each poll answers with a later frame or, after its bounded wait, the
  // same one; passes of 48 pixels come far sooner than 400 polls' time.
  for (auto poll = 0; poll < 400 && (next.is_null() || next["frame"].get<int>() <= frame);
       poll++) {
    auto result = server.client().Get(
        ("/api/state?after=" + std::to_string(frame)).c_str(), server.headers());
    ASSERT_TRUE(result);
    ASSERT_EQ(result->status, 200) << result->body;
    next = json::parse(result->body);
  }
  EXPECT_GT(next["frame"].get<int>(), frame);
  // A frame that will not come for a long time: the poll still answers.
  auto result = server.client().Get("/api/state?after=100000000", server.headers());
  ASSERT_TRUE(result);
  EXPECT_EQ(result->status, 200);
  EXPECT_LT(json::parse(result->body)["frame"].get<int>(), 100000000);
}

TEST(serve, a_saved_scene_renders_the_served_image) {
  auto folder = serve_folder{};
  auto server = test_server{folder, 16};
  ASSERT_TRUE(server.wait_frame(0, 1));
  auto edits = std::vector<std::string>{
      R"({"material":0,"parameter":"pheomelanin","value":1.5})",
      R"({"material":0,"parameter":"beta_m","value":0.2})",
  };
  for (auto& body : edits) ASSERT_EQ(server.post("/api/material", body)->status, 200);
  ASSERT_EQ(server.post("/api/environment", R"({"environment":0,"strength":1.5})")->status, 200);
  ASSERT_EQ(server.post("/api/camera", R"({"orbit":[0.4,0.1],"zoom":0.8})")->status, 200);
  ASSERT_TRUE(server.wait_frame(4, 16));
  auto saved = server.post("/api/save", "");
  ASSERT_TRUE(saved);
  ASSERT_EQ(saved->status, 200) << saved->body;
  auto files = json::parse(saved->body);
  EXPECT_EQ(files["samples"], 16);
  for (auto key : {"image", "png", "scene"})
    EXPECT_TRUE(fs::exists(files[key].get<std::string>())) << key;
  auto rendered = (folder.path / "rendered.exr").string();
  auto result   = run_yscene("render " + files["scene"].get<std::string>() + " -o " + rendered +
                           " --threads 2 -q");
  ASSERT_EQ(result.status, 0) << result.output;
  auto served = texture_data{}, again = texture_data{};
  auto error  = std::string{};
  ASSERT_TRUE(load_image(files["image"].get<std::string>(), served, error)) << error;
  ASSERT_TRUE(load_image(rendered, again, error)) << error;
  ASSERT_EQ(served.width, again.width);
  ASSERT_EQ(served.height, again.height);
  // The same settings and seed: the same samples, but for the rounding of
  // the camera's frame through the json's decimal digits.
  EXPECT_NEAR(mean_value(again) / mean_value(served), 1, 0.01);
  EXPECT_LT(mean_difference(served, again), 0.02 * mean_value(served));
  // A second save takes the next number and leaves the first as it was.
  auto second = server.post("/api/save", R"({"exposure":1})");
  ASSERT_EQ(second->status, 200);
  EXPECT_NE(json::parse(second->body)["scene"], files["scene"]);
  // A save that cannot write the scene's shapes (a file where their folder
  // goes) answers 500 and leaves none of its three files.
  auto before = std::vector<fs::path>{};
  for (auto& entry : fs::directory_iterator(folder.path / "out")) before.push_back(entry.path());
  fs::remove_all(folder.path / "out" / "shapes");
  std::ofstream(folder.path / "out" / "shapes") << "in the way";
  auto third = server.post("/api/save", "");
  ASSERT_TRUE(third);
  EXPECT_EQ(third->status, 500) << third->body;
  EXPECT_NE(third->body.find("error"), std::string::npos) << third->body;
  auto after = 0;
  for (auto& entry : fs::directory_iterator(folder.path / "out"))
    after += entry.path().filename() != "shapes" &&
             std::find(before.begin(), before.end(), entry.path()) == before.end();
  EXPECT_EQ(after, 0);
}

TEST(serve, many_clients_and_broken_connections_do_not_break_it) {
  auto folder = serve_folder{};
  auto server = test_server{folder, 1 << 20};
  ASSERT_TRUE(server.wait_frame(0, 1));
  auto failures = std::atomic<int>{0};
  auto clients  = std::vector<std::thread>{};
  for (auto c = 0; c < 6; c++) {
    clients.emplace_back([&, c] {
      for (auto n = 0; n < 15; n++) {
        if (c % 3 == 0) {
          auto body = json{{"material", 0}, {"parameter", "eumelanin"},
              {"value", 0.3 + 0.1 * n}}.dump();
          auto result = server.post("/api/material", body);
          if (!result || result->status != 200) failures++;
        } else if (c % 3 == 1) {
          auto result = server.client().Get("/api/frame.png", server.headers());
          if (!result || result->status != 200 ||
              result->get_header_value("Content-Type") != "image/png")
            failures++;
        } else {
          if (server.get_state().is_null()) failures++;
          // A client that sends half a request and goes away.
          auto socket_fd = socket(AF_INET, SOCK_STREAM, 0);
          auto address   = sockaddr_in{};
          address.sin_family      = AF_INET;
          address.sin_port        = htons(server.server.port);
          address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
          if (connect(socket_fd, (sockaddr*)&address, sizeof(address)) == 0) {
            auto partial = std::string("POST /api/material HTTP/1.1\r\nContent-Length: 100\r\n"
                                       "X-Token: ") + server.token + "\r\n\r\n{\"mat";
            (void)!write(socket_fd, partial.data(), partial.size());
          }
          close(socket_fd);
        }
      }
    });
  }
  for (auto& client : clients) client.join();
  EXPECT_EQ(failures, 0);
  auto state = server.get_state();
  EXPECT_EQ(state["generation"], 30);  // two editing clients, 15 edits each
  ASSERT_TRUE(server.wait_frame(30, 1));
  auto frame = server.get_frame(folder.path);
  EXPECT_EQ(frame.width, state["width"].get<int>());
}
