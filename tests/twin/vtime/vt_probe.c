/* A probe for the virtual-time library (tests/twin/master_vtime_test.cpp): plain C and libc, as
 * a master we did not write is. Each mode makes the intercepted calls and prints what they
 * returned ("NAME VALUE" lines, times in ns on the monotonic clock) so the test can compare them
 * with what the kernel would give on the simulated clock; the regression modes each repeat a
 * defect found in review; the other modes are the bad masters (exits early, crashes, never
 * waits, ignores SIGTERM, outlives its grace then fails, fails its shutdown, forks). Built
 * dynamic and static. */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/ioctl.h>
#include <sys/select.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <sys/timerfd.h>
#include <sys/wait.h>
#include <netinet/in.h>
#include <time.h>
#include <unistd.h>

static volatile sig_atomic_t term_flag;
static void on_term_flag(int sig) {
  (void)sig;
  term_flag = 1;
}

static long long mono(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (long long)t.tv_sec * 1000000000LL + t.tv_nsec;
}

static void out(const char* name, long long v) {
  printf("%s %lld\n", name, v);
  fflush(stdout);
}

static int quiet_socket(void) { /* a UDP socket nobody sends to */
  int s = socket(AF_INET, SOCK_DGRAM, 0);
  struct sockaddr_in a;
  memset(&a, 0, sizeof a);
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  bind(s, (struct sockaddr*)&a, sizeof a);
  return s;
}

static pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
static pthread_cond_t cv = PTHREAD_COND_INITIALIZER;

static void* ticker(void* arg) {
  const long period_us = (long)(intptr_t)arg;
  for (int i = 0; i < 3; ++i) {
    usleep((useconds_t)period_us);
    pthread_mutex_lock(&mu);
    printf("tick%ld %lld\n", period_us, mono());
    fflush(stdout);
    pthread_mutex_unlock(&mu);
  }
  return NULL;
}

/* The rest of the calls, after calls() (t4 = after_join): the other receive and wait
 * variants, the C11 clock, an absolute timerfd, a clock-read spin and a clockwait. */
static void more_calls(int s) {
  char buf[64];
  struct timespec t;
  timespec_get(&t, TIME_UTC);
  out("timespec_get_s", t.tv_sec);
  /* the socket's SO_RCVTIMEO (rounded as the kernel holds it) applies to each receive */
  struct sockaddr_in from;
  socklen_t fl = sizeof from;
  errno = 0;
  out("recvfrom_rc", recvfrom(s, buf, sizeof buf, 0, (struct sockaddr*)&from, &fl));
  out("recvfrom_errno", errno);
  out("after_recvfrom", mono());
  struct iovec iov = {buf, sizeof buf};
  struct msghdr mh;
  memset(&mh, 0, sizeof mh);
  mh.msg_iov = &iov;
  mh.msg_iovlen = 1;
  errno = 0;
  out("recvmsg_rc", recvmsg(s, &mh, 0));
  out("recvmsg_errno", errno);
  out("after_recvmsg", mono());
  errno = 0;
  out("read_rc", read(s, buf, sizeof buf));
  out("read_errno", errno);
  out("after_read", mono());
  /* pselect and epoll_pwait time out */
  struct timespec ps = {0, 3000000};
  out("pselect_rc", pselect(0, NULL, NULL, NULL, &ps, NULL));
  out("after_pselect", mono());
  int ep = epoll_create1(0);
  struct epoll_event ev;
  out("epoll_pwait_rc", epoll_pwait(ep, &ev, 1, 4, NULL));
  out("after_epoll_pwait", mono());
  /* a timerfd armed at an absolute monotonic instant 2 ms ahead, then read once */
  int tf = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK);
  uint64_t n = 0;
  errno = 0;
  out("timerfd_empty_rc", read(tf, &n, sizeof n));
  out("timerfd_empty_errno", errno);
  struct itimerspec its;
  memset(&its, 0, sizeof its);
  long long at = mono() + 2000000;
  its.it_value.tv_sec = at / 1000000000LL;
  its.it_value.tv_nsec = at % 1000000000LL;
  timerfd_settime(tf, TFD_TIMER_ABSTIME, &its, NULL);
  struct pollfd p = {tf, POLLIN, 0};
  out("timerfd_poll_rc", poll(&p, 1, -1));
  out("timerfd_abs_read_rc", read(tf, &n, sizeof n));
  out("after_timerfd_abs", mono());
  close(tf);
  /* a busy wait on clock reads alone: 2 ms pass in 1 µs steps, one per 64 reads */
  const long long until = mono() + 2000000;
  while (mono() < until) {
  }
  out("after_spin_clock", mono());
  /* pthread_cond_clockwait on the monotonic clock */
  struct timespec cw;
  clock_gettime(CLOCK_MONOTONIC, &cw);
  cw.tv_nsec += 1000000;
  if (cw.tv_nsec >= 1000000000) { cw.tv_nsec -= 1000000000; ++cw.tv_sec; }
  pthread_mutex_lock(&mu);
  out("clockwait_rc", pthread_cond_clockwait(&cv, &mu, CLOCK_MONOTONIC, &cw));
  pthread_mutex_unlock(&mu);
  out("after_clockwait", mono());
}

static int calls(void) {
  struct timespec t;
  out("mono", mono());
  clock_gettime(CLOCK_REALTIME, &t);
  out("real_s", t.tv_sec);
  clock_gettime(CLOCK_BOOTTIME, &t);
  out("boot", (long long)t.tv_sec * 1000000000LL + t.tv_nsec);
  struct timeval tv;
  gettimeofday(&tv, NULL);
  out("tod_s", tv.tv_sec);
  out("time", (long long)time(NULL));
  /* sleeps */
  struct timespec d = {0, 1500000};
  out("nanosleep_rc", nanosleep(&d, NULL));
  out("after_nanosleep", mono());
  struct timespec abs = {1000, 10000000};
  out("abs_rc", clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &abs, NULL));
  out("after_abs", mono());
  struct timespec past = {999, 0};
  out("past_rc", clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &past, NULL));
  out("after_past", mono());
  struct timespec bad = {0, 1000000000};
  out("bad_rc", clock_nanosleep(CLOCK_MONOTONIC, 0, &bad, NULL));
  errno = 0;
  out("bad_nanosleep_rc", nanosleep(&bad, NULL));
  out("bad_nanosleep_errno", errno);
  out("usleep_rc", usleep(250));
  out("after_usleep", mono());
  out("sleep_rc", sleep(1));
  out("after_sleep", mono());
  /* descriptor waits */
  out("poll_rc", poll(NULL, 0, 7));
  out("after_poll", mono());
  struct timeval st = {0, 3000};
  out("select_rc", select(0, NULL, NULL, NULL, &st));
  out("select_tv", st.tv_sec * 1000000LL + st.tv_usec);
  out("after_select", mono());
  struct timespec pt = {0, 2000000};
  out("ppoll_rc", ppoll(NULL, 0, &pt, NULL));
  out("after_ppoll", mono());
  int ep = epoll_create1(0);
  struct epoll_event ev;
  out("epoll_rc", epoll_wait(ep, &ev, 1, 2));
  out("after_epoll", mono());
  /* a UDP socket that nothing reaches: receive timeouts */
  int s = quiet_socket();
  struct timeval rt = {0, 5000};
  setsockopt(s, SOL_SOCKET, SO_RCVTIMEO, &rt, sizeof rt);
  socklen_t rl = sizeof rt;
  getsockopt(s, SOL_SOCKET, SO_RCVTIMEO, &rt, &rl); /* the kernel keeps it in jiffies: rounded up */
  out("rcvtimeo_ns", (rt.tv_sec * 1000000LL + rt.tv_usec) * 1000LL);
  char buf[64];
  errno = 0;
  out("recv_rc", recv(s, buf, sizeof buf, 0));
  out("recv_errno", errno);
  out("after_recv", mono());
  long long before = mono();
  /* the busy-poll rule: after_recv and before are calls 1 and 2, these 61 make 63, the next 64 */
  for (int i = 0; i < 61; ++i) recv(s, buf, sizeof buf, MSG_DONTWAIT);
  (void)before;
  errno = 0;
  out("dontwait_rc", recv(s, buf, sizeof buf, MSG_DONTWAIT));
  out("dontwait_errno", errno);
  out("after_spin", mono());
  /* a datagram to itself is there at once: no time passes */
  struct sockaddr_in a;
  socklen_t al = sizeof a;
  getsockname(s, (struct sockaddr*)&a, &al);
  sendto(s, "x", 1, 0, (struct sockaddr*)&a, sizeof a);
  out("self_rc", recv(s, buf, sizeof buf, 0));
  out("after_self", mono());
  /* a periodic timerfd */
  int tf = timerfd_create(CLOCK_MONOTONIC, 0);
  struct itimerspec its = {{0, 1000000}, {0, 1000000}};
  out("timerfd_settime_rc", timerfd_settime(tf, 0, &its, NULL));
  for (int i = 0; i < 3; ++i) {
    uint64_t n = 0;
    out("timerfd_read_rc", read(tf, &n, sizeof n));
    out("timerfd_n", (long long)n);
    out("after_timerfd", mono());
  }
  struct itimerspec cur;
  timerfd_gettime(tf, &cur);
  out("timerfd_left", cur.it_value.tv_nsec);
  close(tf);
  /* a condition variable nobody signals */
  struct timespec until;
  clock_gettime(CLOCK_REALTIME, &until);
  until.tv_nsec += 4000000;
  if (until.tv_nsec >= 1000000000) { until.tv_nsec -= 1000000000; ++until.tv_sec; }
  pthread_mutex_lock(&mu);
  out("cond_rc", pthread_cond_timedwait(&cv, &mu, &until));
  pthread_mutex_unlock(&mu);
  out("after_cond", mono());
  /* two threads on their own periods, joined */
  pthread_t t1, t2;
  pthread_create(&t1, NULL, ticker, (void*)(intptr_t)3000);
  pthread_create(&t2, NULL, ticker, (void*)(intptr_t)5000);
  pthread_join(t1, NULL);
  pthread_join(t2, NULL);
  out("after_join", mono());
  more_calls(s);
  return 0;
}

/* ---- the regression modes (one per defect found in review; "NAME VALUE" lines, times as
 * differences in ns) ---- */
static long long t0;
static long long since(void) { return mono() - t0; }

static void* sleep_1ms(void* arg) {
  (void)arg;
  usleep(1000);
  return NULL;
}

/* pthread_join after glibc reused an ended (joined) thread's id */
static int join_reuse(void) {
  pthread_t prev = 0;
  int reused = 0;
  for (int i = 0; i < 4; ++i) {
    pthread_t t;
    pthread_create(&t, NULL, sleep_1ms, NULL);
    if (i > 0 && pthread_equal(t, prev)) ++reused;
    prev = t;
    t0 = mono();
    pthread_join(t, NULL);
    out("join_took", since());
  }
  out("join_reused", reused);
  return 0;
}

/* a thread's own write wakes another thread's wait at once, not at the next deadline */
static int wake_fd;
static void* wait_on_fd(void* arg) {
  (void)arg;
  struct pollfd p = {wake_fd, POLLIN, 0};
  const int r = poll(&p, 1, 1000);
  out("wake_rc", r);
  out("wake_after", since());
  return NULL;
}
static void wake_by(int rfd, int wfd, const void* what, size_t len) {
  wake_fd = rfd;
  t0 = mono();
  pthread_t t;
  pthread_create(&t, NULL, wait_on_fd, NULL);
  usleep(1000); /* the waiter blocks */
  ssize_t w = write(wfd, what, len);
  (void)w;
  usleep(200000);
  pthread_join(t, NULL);
}
static int self_wake(void) {
  int pfd[2];
  if (pipe(pfd) != 0) return 1;
  wake_by(pfd[0], pfd[1], "x", 1);
  int efd = eventfd(0, 0);
  uint64_t one = 1;
  wake_by(efd, efd, &one, sizeof one);
  return 0;
}

/* a wall-clock SIGALRM whose handler reads the clock (async-signal-safe) while the loop's own
 * clock reads hold the library's lock */
static volatile long alarm_runs, alarm_off_clock;
static void on_alarm(int sig) {
  (void)sig;
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  if (t.tv_sec < 1000 || t.tv_sec >= 1100) ++alarm_off_clock; /* not the simulated clock */
  ++alarm_runs;
}
static int signal_clock(void) {
  signal(SIGALRM, on_alarm);
  struct itimerval it = {{0, 20}, {0, 20}};
  setitimer(ITIMER_REAL, &it, NULL);
  for (long i = 0; i < 5000000 && alarm_runs < 5000; ++i) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
  }
  struct itimerval off = {{0, 0}, {0, 0}};
  setitimer(ITIMER_REAL, &off, NULL);
  out("alarm_runs", alarm_runs);
  out("alarm_off_clock", alarm_off_clock);
  return 0;
}

/* an absolute timerfd on CLOCK_REALTIME, 2 ms ahead */
static int timerfd_realtime(void) {
  int tf = timerfd_create(CLOCK_REALTIME, 0);
  struct timespec now;
  clock_gettime(CLOCK_REALTIME, &now);
  long long at = (long long)now.tv_sec * 1000000000LL + now.tv_nsec + 2000000;
  struct itimerspec its = {{0, 0}, {at / 1000000000LL, at % 1000000000LL}};
  out("rt_settime_rc", timerfd_settime(tf, TFD_TIMER_ABSTIME, &its, NULL));
  struct itimerspec cur;
  timerfd_gettime(tf, &cur);
  out("rt_left", (long long)cur.it_value.tv_sec * 1000000000LL + cur.it_value.tv_nsec);
  t0 = mono();
  struct pollfd p = {tf, POLLIN, 0};
  out("rt_poll_rc", poll(&p, 1, 50));
  out("rt_after", since());
  return 0;
}

/* a 2 ms timeout that ends as a 2 ms periodic timerfd expires: ready, not a timeout */
static int tie(void) {
  int tf = timerfd_create(CLOCK_MONOTONIC, 0);
  struct itimerspec its = {{0, 2000000}, {0, 2000000}};
  timerfd_settime(tf, 0, &its, NULL);
  t0 = mono();
  uint64_t n;
  struct pollfd p = {tf, POLLIN, 0};
  out("tie_poll_rc", poll(&p, 1, 2));
  out("tie_poll_revents", p.revents);
  out("tie_poll_at", since());
  if (read(tf, &n, sizeof n) != 8) return 1;
  fd_set r;
  FD_ZERO(&r);
  FD_SET(tf, &r);
  struct timeval tv = {0, 2000};
  out("tie_select_rc", select(tf + 1, &r, NULL, NULL, &tv));
  out("tie_select_set", FD_ISSET(tf, &r) ? 1 : 0);
  if (read(tf, &n, sizeof n) != 8) return 1;
  int ep = epoll_create1(0);
  struct epoll_event ev = {EPOLLIN, {.fd = tf}};
  epoll_ctl(ep, EPOLL_CTL_ADD, tf, &ev);
  out("tie_epoll_rc", epoll_wait(ep, &ev, 1, 2));
  out("tie_epoll_at", since());
  return 0;
}

/* a thread that yields with zero or past sleeps until another one sets a flag 1 ms later */
static volatile int flag;
static void* set_flag(void* arg) {
  (void)arg;
  usleep(1000);
  flag = 1;
  return NULL;
}
static int yield_zero(void) {
  const char* names[] = {"usleep0", "nanosleep0", "past_abs"};
  for (int k = 0; k < 3; ++k) {
    flag = 0;
    t0 = mono();
    pthread_t t;
    pthread_create(&t, NULL, set_flag, NULL);
    long calls = 0;
    while (!flag && calls < 300000) {
      struct timespec zero = {0, 0}, past = {1, 0};
      if (k == 0) usleep(0);
      if (k == 1) nanosleep(&zero, NULL);
      if (k == 2) clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &past, NULL);
      ++calls;
    }
    char name[32];
    snprintf(name, sizeof name, "%s_flag", names[k]);
    out(name, flag);
    snprintf(name, sizeof name, "%s_at", names[k]);
    out(name, since());
    pthread_join(t, NULL);
  }
  return 0;
}

/* select writes the time left into its timeval when a descriptor became ready after a wait */
static int select_remaining(void) {
  int tf = timerfd_create(CLOCK_MONOTONIC, 0);
  struct itimerspec its = {{0, 0}, {0, 30000000}};
  timerfd_settime(tf, 0, &its, NULL);
  fd_set r;
  FD_ZERO(&r);
  FD_SET(tf, &r);
  struct timeval tv = {0, 100000};
  out("selrem_rc", select(tf + 1, &r, NULL, NULL, &tv));
  out("selrem_left_us", tv.tv_sec * 1000000LL + tv.tv_usec);
  return 0;
}

/* waits "for ever" (timeouts beyond 2^63 ns): none of them may return within 1 s. 18446744074 s
 * (584 years) is 2^64 ns and 0.29 s, LONG_MAX s wraps to -1 s in 64-bit ns. */
static volatile int returned;
static void* forever(void* arg) {
  const long k = (long)(intptr_t)arg;
  struct timespec big = {LONG_MAX, 0}, rel = {18446744074L, 0};
  int r = 0;
  switch (k) {
    case 0: r = nanosleep(&big, NULL); break;
    case 1: r = clock_nanosleep(CLOCK_MONOTONIC, 0, &rel, NULL); break;
    case 2: r = clock_nanosleep(CLOCK_REALTIME, TIMER_ABSTIME, &big, NULL); break;
    case 3: r = ppoll(NULL, 0, &rel, NULL); break;
    case 4: r = pselect(0, NULL, NULL, NULL, &rel, NULL); break;
    case 5: {
      struct timeval tv = {18446744074L, 0};
      r = select(0, NULL, NULL, NULL, &tv);
      break;
    }
    case 6: {
      pthread_mutex_t m = PTHREAD_MUTEX_INITIALIZER;
      pthread_cond_t c = PTHREAD_COND_INITIALIZER;
      pthread_mutex_lock(&m);
      r = pthread_cond_timedwait(&c, &m, &big);
      pthread_mutex_unlock(&m);
      break;
    }
    case 7: {
      int tf = timerfd_create(CLOCK_MONOTONIC, 0);
      struct itimerspec its = {{0, 0}, {18446744074L, 0}};
      timerfd_settime(tf, 0, &its, NULL);
      uint64_t n;
      r = (int)read(tf, &n, sizeof n);
      break;
    }
  }
  pthread_mutex_lock(&mu);
  printf("forever%ld_rc %d\n", k, r);
  fflush(stdout);
  ++returned;
  pthread_mutex_unlock(&mu);
  return NULL;
}
static int forevers(void) {
  for (long k = 0; k < 8; ++k) {
    pthread_t t;
    pthread_create(&t, NULL, forever, (void*)(intptr_t)k);
  }
  sleep(1);
  pthread_mutex_lock(&mu);
  out("forever_returned", returned);
  pthread_mutex_unlock(&mu);
  _exit(0); /* the others still wait */
}

/* recv(MSG_WAITALL) on a blocking stream socket: all of it, or what came by SO_RCVTIMEO */
static int sv[2];
static void* write_pieces(void* arg) {
  (void)arg;
  ssize_t w = write(sv[1], "ab", 2);
  usleep(1000);
  w = write(sv[1], "cd", 2);
  usleep(1000);
  w = write(sv[1], "ef", 2);
  (void)w;
  return NULL;
}
static int waitall(void) {
  socketpair(AF_UNIX, SOCK_STREAM, 0, sv);
  t0 = mono();
  pthread_t t;
  pthread_create(&t, NULL, write_pieces, NULL);
  usleep(100);
  char b[8];
  out("waitall_rc", recv(sv[0], b, 4, MSG_WAITALL));
  out("waitall_ok", memcmp(b, "abcd", 4) == 0);
  out("waitall_at", since());
  struct timeval rt = {0, 5000};
  setsockopt(sv[0], SOL_SOCKET, SO_RCVTIMEO, &rt, sizeof rt);
  socklen_t rl = sizeof rt;
  getsockopt(sv[0], SOL_SOCKET, SO_RCVTIMEO, &rt, &rl);
  out("waitall_rcvtimeo_ns", (rt.tv_sec * 1000000LL + rt.tv_usec) * 1000LL);
  out("waitall_part_rc", recvfrom(sv[0], b, 4, MSG_WAITALL, NULL, NULL));
  out("waitall_part_at", since());
  pthread_join(t, NULL);
  return 0;
}

/* gettimeofday with only the (obsolete) timezone */
static int gtod_null(void) {
  struct timezone tz;
  struct timeval* volatile none = NULL; /* glibc declares it non-null; the kernel takes NULL */
  out("gtod_null_rc", gettimeofday(none, &tz));
  return 0;
}

/* timerfd flags: O_NONBLOCK set later (fcntl, FIONBIO) and cleared again; settime's checks */
static int timerfd_flags(void) {
  t0 = mono();
  uint64_t n;
  int tf = timerfd_create(CLOCK_MONOTONIC, 0);
  fcntl(tf, F_SETFL, fcntl(tf, F_GETFL) | O_NONBLOCK);
  errno = 0;
  out("fcntl_read_rc", read(tf, &n, sizeof n));
  out("fcntl_read_errno", errno);
  int tf2 = timerfd_create(CLOCK_MONOTONIC, 0);
  int on = 1;
  ioctl(tf2, FIONBIO, &on);
  errno = 0;
  out("fionbio_read_rc", read(tf2, &n, sizeof n));
  out("fionbio_read_errno", errno);
  out("nonblock_at", since());
  /* blocking again: a read waits for the expiry */
  fcntl(tf, F_SETFL, fcntl(tf, F_GETFL) & ~O_NONBLOCK);
  struct itimerspec its = {{0, 0}, {0, 1000000}};
  timerfd_settime(tf, 0, &its, NULL);
  out("blocking_read_rc", read(tf, &n, sizeof n));
  out("blocking_read_at", since());
  struct itimerspec neg = {{0, 0}, {-1, 0}};
  errno = 0;
  out("neg_rc", timerfd_settime(tf, 0, &neg, NULL));
  out("neg_errno", errno);
  struct itimerspec neg_iv = {{-1, 0}, {1, 0}};
  errno = 0;
  out("neg_interval_rc", timerfd_settime(tf, 0, &neg_iv, NULL));
  out("neg_interval_errno", errno);
  struct itimerspec one = {{0, 0}, {1, 0}};
  errno = 0;
  out("bad_flags_rc", timerfd_settime(tf, 4, &one, NULL));
  out("bad_flags_errno", errno);
  return 0;
}

/* poll on more than 64 descriptors, the one that becomes ready last */
static void* write_after_1ms(void* arg) {
  usleep(1000);
  ssize_t w = write((int)(intptr_t)arg, "x", 1);
  (void)w;
  return NULL;
}
static int many_fds(void) {
  enum { kN = 100 };
  struct pollfd p[kN];
  for (int i = 0; i < kN; ++i) p[i] = (struct pollfd){-1, POLLIN, 0};
  int pfd[2];
  if (pipe(pfd) != 0) return 1;
  p[kN - 1].fd = pfd[0];
  t0 = mono();
  pthread_t t;
  pthread_create(&t, NULL, write_after_1ms, (void*)(intptr_t)pfd[1]);
  out("many_rc", poll(p, kN, 1000));
  out("many_at", since());
  pthread_join(t, NULL);
  return 0;
}

/* Waits for ever (or 100 s) in one call until the SIGTERM of the run's end. Its handler sets a
 * flag; the call must end with EINTR at the SIGTERM's instant, as on Linux (it waited on, and
 * the run served it for its whole grace). `how`: the call; "recv-restart" has a handler with
 * SA_RESTART (the receive goes on: Linux restarts it); "siginterrupt" installs with signal() and
 * then siginterrupt(SIGTERM, 1) (the receive ends); "oneshot" has an SA_RESETHAND handler;
 * "ppoll-mask", "pselect-mask" and "epoll-mask" block SIGTERM and wait with a mask that lets it
 * in (the race-free pattern); "default": no handler, nanosleep (the signal kills it in its
 * wait). A second thread waits last, on a pipe nobody writes, so that it, not the main thread
 * that takes the signal, leads the waits; a signal ends only the wait of the thread that ran
 * its handler. */
static void* wait_on_pipe(void* arg) {
  usleep(5000);
  struct pollfd p = {(int)(intptr_t)arg, POLLIN, 0};
  poll(&p, 1, -1);
  return NULL;
}
static int term_in_wait(const char* how) {
  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_handler = on_term_flag;
  sa.sa_flags = !strcmp(how, "recv-restart") ? SA_RESTART : !strcmp(how, "oneshot") ? SA_RESETHAND : 0;
  if (!strcmp(how, "signal")) {
    signal(SIGTERM, on_term_flag); /* BSD semantics; nanosleep still ends */
  } else if (!strcmp(how, "siginterrupt")) {
    signal(SIGTERM, on_term_flag);
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wdeprecated-declarations" /* what programs still call */
    siginterrupt(SIGTERM, 1);
#pragma GCC diagnostic pop
  } else if (strcmp(how, "default") != 0) {
    sigaction(SIGTERM, &sa, NULL); /* default: the signal kills it */
  }
  struct sigaction back;
  sigaction(SIGTERM, NULL, &back);
  out("handler_reads_back", back.sa_handler == on_term_flag);
  out("restart_reads_back", (back.sa_flags & SA_RESTART) != 0);
  const int masked = strstr(how, "-mask") != NULL;
  sigset_t term, open_set;
  sigemptyset(&term);
  sigaddset(&term, SIGTERM);
  sigemptyset(&open_set);
  if (masked) sigprocmask(SIG_BLOCK, &term, NULL); /* SIGTERM only inside the wait */
  int pfd[2];
  if (pipe(pfd) != 0) return 1;
  pthread_t t;
  pthread_create(&t, NULL, wait_on_pipe, (void*)(intptr_t)pfd[0]);
  usleep(1000);
  const long long t0 = mono();
  struct timespec rel = {100, 0}, rem = {0, 0};
  long long rc = 0;
  int still_in_set = -1;
  if (!strcmp(how, "nanosleep") || !strcmp(how, "signal") || !strcmp(how, "default") || !strcmp(how, "oneshot")) {
    rc = nanosleep(&rel, &rem);
  } else if (!strcmp(how, "sleep")) {
    rc = sleep(100);
  } else if (!strcmp(how, "poll")) {
    struct pollfd p = {pfd[0], POLLIN, 0};
    rc = poll(&p, 1, -1);
  } else if (!strcmp(how, "ppoll-mask")) {
    struct pollfd p = {pfd[0], POLLIN, 0};
    rc = ppoll(&p, 1, NULL, &open_set);
  } else if (!strcmp(how, "select") || !strcmp(how, "pselect-mask")) {
    fd_set r;
    FD_ZERO(&r);
    FD_SET(pfd[0], &r);
    rc = masked ? pselect(pfd[0] + 1, &r, NULL, NULL, NULL, &open_set) : select(pfd[0] + 1, &r, NULL, NULL, NULL);
    still_in_set = FD_ISSET(pfd[0], &r) != 0; /* EINTR leaves the sets as they were */
  } else if (!strcmp(how, "epoll") || !strcmp(how, "epoll-mask")) {
    int ep = epoll_create1(0);
    struct epoll_event ev = {EPOLLIN, {0}};
    epoll_ctl(ep, EPOLL_CTL_ADD, pfd[0], &ev);
    rc = masked ? epoll_pwait(ep, &ev, 1, -1, &open_set) : epoll_wait(ep, &ev, 1, -1);
  } else { /* recv, recv-restart, siginterrupt */
    char b[16];
    rc = recv(quiet_socket(), b, sizeof b, 0);
  }
  out("wait_rc", rc);
  out("wait_errno", errno);
  out("wait_flag", term_flag);
  out("wait_ns", mono() - t0);
  out("wait_rem_s", rem.tv_sec);
  out("wait_still_in_set", still_in_set);
  return term_flag ? 0 : 1;
}

/* A signal the process sends itself: at 300 µs the main thread interrupts a thread blocked in a
 * receive (pthread_kill, a handler without SA_RESTART) and joins it. On Linux the receive ends
 * with EINTR at once; no time passes. */
static volatile sig_atomic_t usr1_runs;
static void on_usr1(int sig) {
  (void)sig;
  ++usr1_runs;
}
static long long rx_rc, rx_errno, rx_at;
static void* receive_until_signalled(void* arg) {
  char b[16];
  rx_rc = recv((int)(intptr_t)arg, b, sizeof b, 0);
  rx_errno = errno;
  rx_at = since();
  return NULL;
}
static int self_signal(void) {
  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_handler = on_usr1;
  sigaction(SIGUSR1, &sa, NULL);
  t0 = mono();
  pthread_t t;
  pthread_create(&t, NULL, receive_until_signalled, (void*)(intptr_t)quiet_socket());
  usleep(300);
  pthread_kill(t, SIGUSR1);
  pthread_join(t, NULL);
  out("self_rx_rc", rx_rc);
  out("self_rx_errno", rx_errno);
  out("self_rx_at", rx_at);
  out("self_joined_at", since());
  out("self_usr1_runs", usr1_runs);
  return 0;
}

/* Dispositions through the library's sigaction: SIG_IGN given in a struct that still says
 * SA_SIGINFO is ignored (it was taken for a handler: a crash), signal() refuses SIG_ERR, and the
 * action read back after an SA_RESETHAND handler fired is SIG_DFL without SA_SIGINFO. */
static void on_info(int sig, siginfo_t* si, void* uc) {
  (void)sig;
  (void)si;
  (void)uc;
}
static int dispositions(void) {
  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_sigaction = on_info;
  sa.sa_flags = SA_SIGINFO;
  sigaction(SIGUSR2, &sa, NULL);
  sa.sa_handler = SIG_IGN; /* SA_SIGINFO left in sa_flags */
  sigaction(SIGUSR2, &sa, NULL);
  raise(SIGUSR2);
  out("ignored_survived", 1);
  errno = 0;
  out("signal_sig_err_refused", signal(SIGUSR1, SIG_ERR) == SIG_ERR);
  out("signal_sig_err_errno", errno);
  struct sigaction once;
  memset(&once, 0, sizeof once);
  once.sa_handler = on_usr1;
  once.sa_flags = SA_RESETHAND;
  sigaction(SIGUSR1, &once, NULL);
  raise(SIGUSR1);
  struct sigaction after;
  sigaction(SIGUSR1, NULL, &after);
  out("reset_reads_dfl", after.sa_handler == SIG_DFL);
  out("reset_reads_siginfo", (after.sa_flags & SA_SIGINFO) != 0);
  out("reset_handler_ran", usr1_runs);
  return 0;
}

int main(int argc, char** argv) {
  const char* mode = argc > 1 ? argv[1] : "calls";
  if (!strcmp(mode, "calls")) return calls();
  if (!strcmp(mode, "join-reuse")) return join_reuse();
  if (!strcmp(mode, "self-wake")) return self_wake();
  if (!strcmp(mode, "signal-clock")) return signal_clock();
  if (!strcmp(mode, "timerfd-realtime")) return timerfd_realtime();
  if (!strcmp(mode, "tie")) return tie();
  if (!strcmp(mode, "yield-zero")) return yield_zero();
  if (!strcmp(mode, "select-remaining")) return select_remaining();
  if (!strcmp(mode, "forever")) return forevers();
  if (!strcmp(mode, "waitall")) return waitall();
  if (!strcmp(mode, "gtod-null")) return gtod_null();
  if (!strcmp(mode, "timerfd-flags")) return timerfd_flags();
  if (!strcmp(mode, "many-fds")) return many_fds();
  if (!strcmp(mode, "term-in-wait")) return term_in_wait(argc > 2 ? argv[2] : "nanosleep");
  if (!strcmp(mode, "self-signal")) return self_signal();
  if (!strcmp(mode, "dispositions")) return dispositions();
  if (!strcmp(mode, "waits")) { /* N waits of 1 µs, for tests/bench/bench_vtime_wait.cpp */
    const long n = argc > 2 ? atol(argv[2]) : 1000;
    for (long i = 0; i < n; ++i) usleep(1);
    return 0;
  }
  if (!strcmp(mode, "sleep")) { /* sleeps in 10 ms steps until SIGTERM */
    for (;;) usleep(10000);
  }
  if (!strcmp(mode, "exit-early")) {
    usleep(100000);
    return 0;
  }
  if (!strcmp(mode, "crash")) {
    usleep(100000);
    raise(SIGSEGV);
  }
  if (!strcmp(mode, "busy")) { /* a loop without a single call the library sees */
    usleep(100000);
    volatile unsigned long x = 0;
    for (;;) ++x;
  }
  if (!strcmp(mode, "ignore-term")) {
    signal(SIGTERM, SIG_IGN);
    for (;;) usleep(10000);
  }
  if (!strcmp(mode, "ignore-term-exit-late")) {  /* outlives its grace, then fails by itself */
    signal(SIGTERM, SIG_IGN);
    const long long t0 = mono();
    while (mono() - t0 < 1050000000LL) usleep(10000);  /* 1.05 s on its clock */
    return 1;
  }
  if (!strcmp(mode, "fail-on-term")) {  /* its shutdown fails: exit 1 at the next wake */
    signal(SIGTERM, on_term_flag);
    while (!term_flag) usleep(10000);
    usleep(20000);
    return 1;
  }
  if (!strcmp(mode, "fork")) {
    usleep(100000);
    pid_t p = fork();
    if (p == 0) {
      usleep(1000);
      _exit(0);
    }
    for (;;) usleep(10000);
  }
  fprintf(stderr, "vt_probe: unknown mode %s\n", mode);
  return 2;
}
