// Access control through the real binaries: tokens with roles on gRPC and HTTP, a client
// cancelling only its own jobs, loopback-only without tokens unless --insecure, and TLS.
#include <arpa/inet.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <httplib.h>
#include <netinet/in.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <thread>

#include "core/io/files.h"
#include "tessera.grpc.pb.h"
#include "tests/integration/access_fixture.h"
#include "wire.h"

namespace tessera {
namespace {

TEST_F(Access, EveryCallNeedsATokenWhoseRoleAllowsIt) {
  start_coordinator();
  // No token, or an unknown one: refused, saying what is missing.
  CommandResult r = tessera("jobs", nullptr);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("needs an access token"), std::string::npos) << r.err;
  r = tessera("jobs", "an-unknown-token-0123456789");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("not known"), std::string::npos) << r.err;
  // A viewer reads but may not submit; a worker token may not act as a client.
  EXPECT_EQ(tessera("jobs", kViewer).code, 0);
  r = tessera("submit " + kScene + " " + kFlags, kViewer);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("a viewer token may not"), std::string::npos) << r.err;
  r = tessera("jobs", kWorker);
  EXPECT_NE(r.err.find("a worker token may not"), std::string::npos) << r.err;

  // A client token cannot register as a worker: the worker says why and exits 1.
  Process& impostor = start_worker(kAlice);
  EXPECT_EQ(impostor.wait(20), 1);
  EXPECT_NE(slurp((dir / "worker0.err").string()).find("a client token may not"), std::string::npos);

  // Alice's job; Bob may read it but not cancel it; the admin may.
  const std::string a1 = submit(kAlice), a2 = submit(kAlice);
  EXPECT_EQ(tessera("status " + a1, kBob).code, 0);
  r = tessera("cancel " + a1, kBob);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("only its own jobs"), std::string::npos) << r.err;
  EXPECT_EQ(tessera("cancel " + a1, kAlice).code, 0) << "the owner may";
  EXPECT_EQ(tessera("cancel " + a2, kAdmin).code, 0) << "an admin may";
  EXPECT_NE(tessera("status " + a1 + " --json", kViewer).out.find("\"owner\":\"alice\""), std::string::npos);

  // A worker with a worker token renders Alice's next job: the local image, bit for bit.
  start_worker(kWorker);
  const std::string out = (dir / "farm.exr").string(), local = (dir / "local.exr").string();
  r = tessera("submit " + kScene + " " + kFlags + " --wait -q -f " + out, kAlice);
  ASSERT_EQ(r.code, 0) << r.err;
  ASSERT_EQ(std::system((kBin + "/tessera render " + kScene + " " + kFlags + " -q -f " + local).c_str()), 0);
  expect_same_pixels(local, out);

  // HTTP: 401 (with a Basic challenge, so a browser asks) without a token, 403 for a
  // worker's, 200 for a viewer's as a bearer token or as the Basic password.
  std::string challenge;
  EXPECT_EQ(http_get("/api/status", "", &challenge), 401);
  EXPECT_NE(challenge.find("Basic"), std::string::npos);
  EXPECT_EQ(http_get("/metrics", std::string("Bearer ") + kWorker), 403);
  EXPECT_EQ(http_get("/healthz", ""), 200);  // probes need no token, and say nothing
  EXPECT_EQ(http_get("/readyz", ""), 200);
  EXPECT_EQ(http_get("/api/status", std::string("Bearer ") + kViewer), 200);
  httplib::Client browser("127.0.0.1", http_port);
  browser.set_basic_auth("ops", kViewer);
  auto page = browser.Get("/");
  ASSERT_TRUE(page);
  EXPECT_EQ(page->status, 200);
}

// Issue 23: a worker's id is not enough to act for it. Mallory (holding another worker
// token) knows the honest worker's id (the status page shows it) and tries every worker
// call under it, with its own secret or none: each is refused, and the honest worker, with
// the secret only its registration was given, goes on.
TEST_F(Access, NoWorkerCanActUnderAnothersId) {
  start_coordinator({"--max-workers-per-token", "3"});
  auto stub = v1::TesseraWorker::NewStub(grpc::CreateChannel(grpc_addr, grpc::InsecureChannelCredentials()));
  const v1::RegisterRequest reg = registration();
  v1::RegisterResponse honest, mallory;
  ASSERT_TRUE(stub->Register(call(kWorker).get(), reg, &honest).ok());
  ASSERT_TRUE(stub->Register(call(kMallory).get(), reg, &mallory).ok());
  EXPECT_EQ(honest.worker_secret().size(), 32u);  // 128 bits, hex
  EXPECT_NE(honest.worker_secret(), mallory.worker_secret());
  const auto denied = [](const grpc::Status& st, const std::string& why) {
    EXPECT_EQ(st.error_code(), grpc::StatusCode::PERMISSION_DENIED) << st.error_message();
    EXPECT_NE(st.error_message().find(why), std::string::npos) << st.error_message();
  };
  const std::string not_its = "does not carry that worker's secret";
  for (const std::string& secret : {mallory.worker_secret(), std::string()}) {
    const auto under_honest_id = [&](auto request) {
      request.set_worker_id(honest.worker_id());
      request.set_worker_secret(secret);
      return request;
    };
    v1::HeartbeatRequest hb = under_honest_id(v1::HeartbeatRequest());
    hb.add_task_ids(1);
    v1::HeartbeatResponse hr;
    denied(stub->Heartbeat(call(kMallory).get(), hb, &hr), not_its);
    v1::GetTaskResponse tasks;
    denied(stub->GetTask(call(kMallory).get(), under_honest_id(v1::GetTaskRequest()), &tasks), not_its);
    v1::ReleaseResponse rr;
    denied(stub->ReleaseTask(call(kMallory).get(), under_honest_id(v1::ReleaseRequest()), &rr), not_its);
    v1::UnregisterResponse ur;
    denied(stub->Unregister(call(kMallory).get(), under_honest_id(v1::UnregisterRequest()), &ur), not_its);
    v1::ResultBatch forged = under_honest_id(v1::ResultBatch());
    forged.add_results()->set_worker_id(honest.worker_id());
    v1::ResultAcks acks;
    denied(stub->SubmitResults(call(kMallory).get(), forged, &acks), not_its);
  }
  // Its own batch with a result under the honest id inside.
  v1::ResultBatch smuggled;
  smuggled.set_worker_id(mallory.worker_id());
  smuggled.set_worker_secret(mallory.worker_secret());
  smuggled.add_results()->set_worker_id(honest.worker_id());
  v1::ResultAcks acks;
  denied(stub->SubmitResults(call(kMallory).get(), smuggled, &acks), "a result under worker");
  // The honest worker is still registered, and acts with its secret.
  v1::GetTaskRequest mine;
  mine.set_worker_id(honest.worker_id());
  mine.set_worker_secret(honest.worker_secret());
  v1::GetTaskResponse none;
  EXPECT_TRUE(stub->GetTask(call(kWorker).get(), mine, &none).ok());
  // A registration flood under one token stops at --max-workers-per-token, naming it, and
  // locks no other token's workers out.
  v1::RegisterResponse r;
  EXPECT_TRUE(stub->Register(call(kMallory).get(), reg, &r).ok());
  EXPECT_TRUE(stub->Register(call(kMallory).get(), reg, &r).ok());
  const grpc::Status full = stub->Register(call(kMallory).get(), reg, &r);
  EXPECT_EQ(full.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(full.error_message().find("--max-workers-per-token"), std::string::npos) << full.error_message();
  EXPECT_TRUE(stub->Register(call(kWorker).get(), reg, &r).ok());
}

// Issue 23: a tokens file every user of the machine can read is warned of at start (the
// Kubernetes base mounts it 0440 for that reason); one only its owner reads is not.
TEST_F(Access, AWorldReadableTokensFileIsWarnedOf) {
  const fs::path tokens = dir / "tokens";
  fs::permissions(tokens, fs::perms::owner_read | fs::perms::owner_write | fs::perms::others_read);
  start_coordinator();
  coordinator.reset();
  EXPECT_NE(slurp((dir / "coordinator.err").string()).find("is readable by every user of this machine"),
            std::string::npos);
  fs::permissions(tokens, fs::perms::owner_read | fs::perms::owner_write);
  start_coordinator();
  coordinator.reset();
  EXPECT_EQ(slurp((dir / "coordinator.err").string()).find("readable by every user"), std::string::npos);
}

// Issue 23: slow connections that never finish their request held every thread of the
// status port, /healthz included, so the shipped liveness probe restarted the coordinator
// in a loop. The probes' own listener (--health) answers whatever holds the status port.
TEST_F(Access, ProbesAnswerWhileSlowClientsHoldTheStatusPort) {
  start_coordinator({"--health", "127.0.0.1:0"});
  std::smatch m;
  const std::string line = coordinator->read_line();
  ASSERT_TRUE(std::regex_search(line, m, std::regex("health listening on 127\\.0\\.0\\.1:(\\d+)"))) << line;
  const int health_port = std::stoi(m[1]);
  std::vector<int> slow;  // each sends half a request line, then nothing
  for (int i = 0; i < 64; ++i) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(uint16_t(http_port));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ASSERT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    ASSERT_GT(::send(fd, "GET /api/status HT", 18, 0), 0);
    slow.push_back(fd);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  for (int i = 0; i < 5; ++i) {
    httplib::Client probe("127.0.0.1", health_port);
    probe.set_connection_timeout(1);
    probe.set_read_timeout(1);
    const auto t0 = std::chrono::steady_clock::now();
    auto live = probe.Get("/healthz"), ready = probe.Get("/readyz");
    ASSERT_TRUE(live && ready);
    EXPECT_EQ(live->status, 200);
    EXPECT_EQ(ready->status, 200);
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 1.0);
  }
  for (int fd : slow) ::close(fd);
  coordinator.reset();
  // A malformed --health is refused before any port or the data folder is opened.
  Process bad(kBin + "/tessera-coordinator",
              {"--listen", "127.0.0.1:0", "--http", "127.0.0.1:0", "--data", (dir / "bad").string(), "--health",
               "127.0.0.1:99999"},
              (dir / "bad.err").string());
  EXPECT_NE(bad.wait(20), 0);
  EXPECT_NE(slurp((dir / "bad.err").string()).find("--health: bad port in '127.0.0.1:99999'"), std::string::npos);
  EXPECT_FALSE(fs::exists(dir / "bad"));
}

// The bound on one worker's leases and a worker's own cap take only values that make sense,
// and a wrong one is refused naming the flag before anything starts.
TEST_F(Access, LeaseBoundsOutOfRangeAreRefusedNamingTheFlag) {
  Process coordinator(kBin + "/tessera-coordinator",
                      {"--listen", "127.0.0.1:0", "--http", "127.0.0.1:0", "--data", (dir / "bad").string(),
                       "--max-leases-per-worker", "0"},
                      (dir / "c.err").string());
  EXPECT_NE(coordinator.wait(20), 0);
  EXPECT_NE(slurp((dir / "c.err").string()).find("--max-leases-per-worker: Value 0 not in range"), std::string::npos)
      << slurp((dir / "c.err").string());
  EXPECT_FALSE(fs::exists(dir / "bad"));
  Process worker(kBin + "/tessera-worker", {"--coordinator", "127.0.0.1:1", "--max-leases", "-1"},
                 (dir / "w.err").string());
  EXPECT_NE(worker.wait(20), 0);
  EXPECT_NE(slurp((dir / "w.err").string()).find("--max-leases: Value -1 not in range"), std::string::npos)
      << slurp((dir / "w.err").string());
}

// Issue 24 renamed five options to one spelling across the binaries; the old spellings
// still work (hidden from --help), keep their checks, and say the new name.
TEST_F(Access, OldOptionSpellingsStillWorkAndNameTheNewOne) {
  Process worker(kBin + "/tessera-worker", {"--coordinator", "127.0.0.1:1", "--max-tasks", "-1"},
                 (dir / "w.err").string());
  EXPECT_NE(worker.wait(20), 0);
  EXPECT_NE(slurp((dir / "w.err").string()).find("--max-tasks: Value -1 not in range"), std::string::npos)
      << slurp((dir / "w.err").string());
  Process idle(kBin + "/tessera-worker", {"--coordinator", "127.0.0.1:1", "--exit-when-idle", "0.5"},
               (dir / "idle.err").string());
  EXPECT_EQ(idle.wait(30), 0);
  EXPECT_NE(slurp((dir / "idle.err").string()).find("--exit-when-idle is now spelled --exit-when-idle-seconds"),
            std::string::npos)
      << slurp((dir / "idle.err").string());
  fs::create_directories(dir / "old");
  Process coordinator(kBin + "/tessera-coordinator",
                      {"--listen", "127.0.0.1:0", "--http", "127.0.0.1:0", "--data", (dir / "old").string(), "--tokens",
                       (dir / "no-such-file").string()},
                      (dir / "c.err").string());
  EXPECT_NE(coordinator.wait(20), 0);
  EXPECT_NE(slurp((dir / "c.err").string()).find("no-such-file"), std::string::npos) << slurp((dir / "c.err").string());
}

// Issue 23: SIGTERM stops the coordinator within seconds even while it checks a scene
// that takes far longer to load (a 1 KB glTF whose node graph lists a child twice, 19 deep,
// with a mesh of two primitives: 1 M mesh copies, at the limit of the budgets, ~7 s and 1 GB
// here). The check gives up at its next
// step; the client, told nothing was accepted, keeps trying; the restarted coordinator has
// no job and nothing half-kept.
TEST_F(Access, SigtermStopsTheCoordinatorWithinSecondsDuringASceneCheck) {
  std::string nodes = R"({"mesh":0})";
  for (int i = 1; i <= 19; ++i)
    nodes += ",{\"children\":[" + std::to_string(i - 1) + "," + std::to_string(i - 1) + "]}";
  const std::string scene = (dir / "dag.gltf").string();
  write_file_atomic(scene,
                    R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[19]}],"nodes":[)" + nodes +
                        R"(],"meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1},)"
                        R"({"attributes":{"POSITION":0},"indices":1}]}],)"
                        R"("buffers":[{"byteLength":44,"uri":"data:application/octet-stream;base64,)"
                        R"(AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAIAAAA="}],)"
                        R"("bufferViews":[{"buffer":0,"byteLength":36},{"buffer":0,"byteOffset":36,"byteLength":6}],)"
                        R"("accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3",)"
                        R"("min":[0,0,0],"max":[1,1,0]},{"bufferView":1,"componentType":5123,"count":3,)"
                        R"("type":"SCALAR"}]})");
  start_coordinator();
  const std::string cmd = "env -u TESSERA_TOKEN -u TESSERA_TOKEN_FILE " + kBin + "/tessera submit " + scene +
                          " -r 8 8 -s 1 --coordinator " + grpc_addr + " --token-file " + token_file(kAlice) +
                          " >/dev/null 2>" + (dir / "submit.err").string();
  std::thread client([&] { (void)std::system(("timeout 8 " + cmd).c_str()); });
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));  // into the check
  const auto t0 = std::chrono::steady_clock::now();
  coordinator->signal(SIGTERM);
  EXPECT_EQ(coordinator->wait(30), 0);
  const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_LT(took, 5.0) << "the coordinator took " << took << " s to stop";
  const std::string log = slurp((dir / "coordinator.err").string());
  EXPECT_EQ(log.find("still running"), std::string::npos) << log;  // the check stopped, not abandoned
  start_coordinator();  // the same data folder: no job, and the client's retries get the scene checked
  const CommandResult jobs = tessera("jobs --json", kAlice);
  EXPECT_EQ(jobs.code, 0) << jobs.err;
  EXPECT_EQ(jobs.out.find("dag.gltf"), std::string::npos) << jobs.out;
  coordinator->signal(SIGTERM);
  EXPECT_EQ(coordinator->wait(30), 0);
  client.join();
  EXPECT_EQ(slurp((dir / "coordinator.err").string()).find("internal error"), std::string::npos);
  // The scene was being checked, not refused by a budget at once.
  EXPECT_EQ(slurp((dir / "submit.err").string()).find("over the limit"), std::string::npos)
      << slurp((dir / "submit.err").string());
}

// Issue 23: systemd's default soft limit of 1024 descriptors ran out at about a thousand
// idle connections. The coordinator raises its soft limit to the hard one at start.
TEST_F(Access, TheCoordinatorRaisesItsDescriptorLimit) {
  rlimit r{};
  ASSERT_EQ(getrlimit(RLIMIT_NOFILE, &r), 0);
  if (r.rlim_max != RLIM_INFINITY && r.rlim_max <= 300) GTEST_SKIP() << "hard descriptor limit " << r.rlim_max;
  Process c("/bin/sh",
            {"-c", "ulimit -Sn 256 && exec " + kBin + "/tessera-coordinator --listen 127.0.0.1:0 --http 127.0.0.1:0 " +
                       "--data " + (dir / "data").string()},
            (dir / "limited.err").string());
  ASSERT_NE(c.read_line().find("grpc listening"), std::string::npos);
  std::ifstream limits("/proc/" + std::to_string(c.pid()) + "/limits");
  std::string line, soft, hard;
  while (std::getline(limits, line))
    if (line.rfind("Max open files", 0) == 0) std::istringstream(line.substr(14)) >> soft >> hard;
  ASSERT_FALSE(soft.empty());
  EXPECT_EQ(soft, hard) << "the soft limit is raised to the hard one";
}

// Issue 23: connections that never finish their handshake, or that go idle, are closed
// (--handshake-seconds, --idle-connection-seconds): a thousand such sockets once held a
// thousand descriptors for good. Fifty raw TCP connections that send nothing are closed
// within the handshake time, and the coordinator's descriptors come back to where they were.
TEST_F(Access, HalfOpenAndIdleConnectionsAreClosed) {
  start_coordinator({"--handshake-seconds", "1", "--idle-connection-seconds", "2"});
  const auto open_fds = [&] {
    const fs::path fds = "/proc/" + std::to_string(coordinator->pid()) + "/fd";
    return size_t(std::distance(fs::directory_iterator(fds), fs::directory_iterator()));
  };
  const size_t before = open_fds();
  const int port = std::stoi(grpc_addr.substr(grpc_addr.rfind(':') + 1));
  std::vector<int> socks;
  for (int i = 0; i < 50; ++i) {
    const int fd = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(uint16_t(port));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ASSERT_EQ(connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    socks.push_back(fd);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  EXPECT_GE(open_fds(), before + 40);  // held, for now
  size_t closed = 0;
  for (int fd : socks) {  // each sees the coordinator close it (end of stream) within a few seconds
    timeval tv{5, 0};
    setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    char buf[256];
    ssize_t got;
    while ((got = recv(fd, buf, sizeof buf, 0)) > 0) {
    }
    closed += got == 0 || (got < 0 && errno == ECONNRESET);
    close(fd);
  }
  EXPECT_EQ(closed, socks.size());
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_LE(open_fds(), before + 2);
  // A real client is unaffected: its channel connects again when it next calls.
  EXPECT_EQ(tessera("jobs", kAlice).code, 0);
}

// Issue 22: requeue, priority and delete follow the cancel rule: a client changes only its
// own jobs, a viewer none, an admin any.
TEST_F(Access, ChangingAJobAfterSubmitIsTheOwnersOrAnAdminsRight) {
  start_coordinator();
  const std::string a = submit(kAlice);
  for (const std::string& cmd : {"priority " + a + " 3", "delete " + a, "cancel " + a}) {
    CommandResult r = tessera(cmd, kBob);
    EXPECT_EQ(r.code, 1) << cmd;
    EXPECT_NE(r.err.find("only its own jobs"), std::string::npos) << cmd << ": " << r.err;
    r = tessera(cmd, kViewer);
    EXPECT_NE(r.err.find("a viewer token may not"), std::string::npos) << cmd << ": " << r.err;
  }
  EXPECT_EQ(tessera("priority " + a + " 3", kAlice).code, 0);
  EXPECT_EQ(tessera("cancel " + a, kAlice).code, 0);
  for (int i = 0; i < 100 && tessera("status " + a, kAlice).out.find("CANCELLED") == std::string::npos; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_NE(tessera("requeue " + a, kBob).err.find("only its own jobs"), std::string::npos);
  const CommandResult requeued = tessera("requeue " + a, kAlice);
  EXPECT_EQ(requeued.code, 0) << requeued.err;
  EXPECT_NE(requeued.out.find("QUEUED"), std::string::npos) << requeued.out;
  const CommandResult deleted = tessera("delete " + a, kAdmin);
  EXPECT_EQ(deleted.code, 0) << deleted.err;
  EXPECT_EQ(tessera("jobs", kViewer).out, "");
}

TEST_F(Access, WithoutTokensOnlyLoopbackUnlessInsecure) {
  auto start = [&](std::vector<std::string> args) {
    args.insert(args.end(), {"--http", "127.0.0.1:0", "--data", (dir / "data").string()});
    return std::make_unique<Process>(kBin + "/tessera-coordinator", args, (dir / "c.err").string());
  };
  auto refused = start({"--listen", "0.0.0.0:0"});
  EXPECT_EQ(refused->wait(10), 2);
  EXPECT_NE(slurp((dir / "c.err").string()).find("refusing to listen beyond loopback"), std::string::npos);
  auto open = start({"--listen", "0.0.0.0:0", "--insecure"});
  EXPECT_NE(open->read_line().find("grpc listening on 0.0.0.0:"), std::string::npos);
  open.reset();
  auto local = start({"--listen", "127.0.0.1:0"});
  EXPECT_NE(local->read_line().find("grpc listening on 127.0.0.1:"), std::string::npos);
  local.reset();
  EXPECT_NE(slurp((dir / "c.err").string()).find("loopback only"), std::string::npos);
}

TEST_F(Access, TlsForGrpcAndHttp) {
  if (std::system("command -v openssl >/dev/null 2>&1") != 0)
    GTEST_SKIP() << "no openssl command to make a certificate";
  const std::string cert = (dir / "cert.pem").string(), key = (dir / "key.pem").string();
  ASSERT_EQ(std::system(("openssl req -x509 -newkey rsa:2048 -nodes -days 1 -subj /CN=localhost -addext "
                         "subjectAltName=IP:127.0.0.1,DNS:localhost -keyout " +
                         key + " -out " + cert + " >/dev/null 2>&1")
                            .c_str()),
            0);
  start_coordinator({"--tls-cert", cert, "--tls-key", key});
  start_worker(kWorker, "--tls-ca", cert);
  const std::string out = (dir / "tls.exr").string(), local = (dir / "local.exr").string();
  CommandResult r = tessera("submit " + kScene + " " + kFlags + " --wait -q -f " + out, kAlice, "--tls-ca " + cert);
  ASSERT_EQ(r.code, 0) << r.err;
  ASSERT_EQ(std::system((kBin + "/tessera render " + kScene + " " + kFlags + " -q -f " + local).c_str()), 0);
  expect_same_pixels(local, out);
  // Plaintext is not spoken, and the client says what to do.
  r = tessera("jobs", kAlice);
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("--tls-ca"), std::string::npos) << r.err;
  // HTTPS, verified against the same certificate.
  httplib::SSLClient https("127.0.0.1", http_port);
  https.set_ca_cert_path(cert.c_str());
  https.enable_server_certificate_verification(true);
  auto res = https.Get("/api/status", httplib::Headers{{"Authorization", std::string("Bearer ") + kViewer}});
  ASSERT_TRUE(res) << httplib::to_string(res.error());
  EXPECT_EQ(res->status, 200);
  // Found by an audit: a call's token was checked only once the server had read its request
  // whole, so a stranger's 200 MB submit took 200 MB and more of the coordinator's memory
  // before it was refused. Over TLS the token is checked from the call's metadata first.
  const auto peak_kib = [&] {
    std::ifstream in("/proc/" + std::to_string(coordinator->pid()) + "/status");
    for (std::string line; std::getline(in, line);)
      if (line.rfind("VmHWM:", 0) == 0) return std::stol(line.substr(6));
    return 0L;
  };
  grpc::SslCredentialsOptions ca;
  ca.pem_root_certs = read_file_bytes(cert);
  auto stub = v1::Tessera::NewStub(grpc::CreateChannel(grpc_addr, grpc::SslCredentials(ca)));
  v1::SubmitJobRequest big;
  big.set_main_file("scene.dae");
  v1::SceneFile* f = big.add_files();
  f->set_path("scene.dae");
  f->mutable_content()->assign(200 << 20, 'x');
  const long before = peak_kib();
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  v1::JobId id;
  const grpc::Status st = stub->SubmitJob(&ctx, big, &id);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::UNAUTHENTICATED) << st.error_message();
  EXPECT_NE(st.error_message().find("--token-file"), std::string::npos) << st.error_message();
  EXPECT_LT(peak_kib() - before, 64L << 10) << "KiB more at the coordinator's peak";
}

}  // namespace
}  // namespace tessera
